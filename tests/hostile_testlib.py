"""Pieces shared by the hostile-input tests (`tests/<package>/test_<package>_inputs.py`): a
valid pose and a table of bad ones, tiny cameras, settings and relightable models, and config
and workdir helpers."""

import os

import jax
import numpy as np

from mfsample import orbit_camera
from mfsample.camera import Camera
from mfsample.lighting.field import init_relightable
from mfsample.renderer import RenderSettings
from mfsample.samplers import SamplerSpec

NAN = float("nan")


def _pose():
  """A valid [4, 4] world-to-camera (numpy float64)."""
  return np.asarray(orbit_camera(0.3, 0.4, width=16, height=16, distance=3.0).world_to_camera,
                    np.float64)


def _rot_x(deg):
  a = np.radians(deg)
  m = np.eye(4)
  m[1:3, 1:3] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
  return m


W2C = _pose()
BAD_POSES = {  # name: (world_to_camera, fx, fy, cx, cy, expected message)
    "nan pose": (np.where(np.eye(4) > 0, NAN, W2C), 8.0, 8.0, 8.0, 8.0, "non-finite"),
    "inf translation": (W2C + np.pad(np.full((3, 1), np.inf), ((0, 1), (3, 0))), 8.0, 8.0,
                        8.0, 8.0, "non-finite"),
    "scaled 1.01": (np.diag([1.01, 1.01, 1.01, 1.0]) @ W2C, 8.0, 8.0, 8.0, 8.0, "not rigid"),
    "sheared": (W2C + np.pad([[0.0, 0.01, 0.0]], ((0, 3), (0, 1))), 8.0, 8.0, 8.0, 8.0,
                "not rigid"),
    "reflected": (np.diag([1.0, 1.0, -1.0, 1.0]) @ W2C, 8.0, 8.0, 8.0, 8.0, "reflection"),
    "projective bottom row": (W2C + np.pad([[0.0, 0.0, 0.5, 0.0]], ((3, 0), (0, 0))), 8.0,
                              8.0, 8.0, 8.0, "bottom row"),
    "fx = 0": (W2C, 0.0, 8.0, 8.0, 8.0, r"fx = 0.0 must be > 0"),
    "fy < 0": (W2C, 8.0, -3.0, 8.0, 8.0, r"fy = -3.0 must be > 0"),
    "nan fx": (W2C, NAN, 8.0, 8.0, 8.0, "fx is not finite"),
    "inf cy": (W2C, 8.0, 8.0, 8.0, np.inf, "cy is not finite"),
}


SMALL = RenderSettings(max_intersections=2048, chunk_size=8, chunks_per_step=4)


POINTS = np.random.default_rng(0).uniform(-1, 1, (5, 3))


RELIGHTABLE = SamplerSpec(kind="lowrank", rank=2, groups=("transfer_dc",),
                          bounds=(("transfer_dc", 0.5),))


def _cams(num=2):
  """`num` valid 8 x 8 cameras batched over one axis."""
  return Camera.create(np.stack([W2C] * num), 6.0, 6.0, 4.0, 4.0, 8, 8)


def _relightable():
  """An untrained relightable model (m = 1, n = 4) whose samples differ (B_hat over T)."""
  return init_relightable(jax.random.PRNGKey(0), POINTS * 0.3, spec=RELIGHTABLE, out_coeffs=1,
                          light_coeffs=4, init_scales={"transfer_dc": 0.2}, init_opacity=0.6)


def _set(config, field, value):
  *parents, leaf = field.split(".")
  node = config
  for p in parents:
    node = node[p]
  with config.unlocked():
    node[leaf] = value


def _tree_files(root):
  return sorted((os.path.relpath(os.path.join(d, n), root), os.path.getmtime(os.path.join(d, n)))
                for d, _, names in os.walk(root) for n in names)
