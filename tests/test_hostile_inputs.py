"""Hostile inputs: for every public entry point, a table of bad inputs and what they give.

Each row is a bad input and its expected outcome: a clear error whose message names the
field or the file, or a defined behaviour (docs/reliability.md lists the same tables).
Kill-and-resume and corrupt-file tests compare against uninterrupted runs. Tiny sizes
throughout: the compiled functions are those of tests/test_train.py and the tiny planning
config, so a full suite compiles them once.
"""

import json
import os
import shutil
import struct
import zlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from absl import flags
from conftest import tiny_config, train_with
from ml_collections import config_flags
from PIL import Image
from planning_testlib import random_model
from test_train import resume_config

from configs import camera_planning
from mfsample import _json, config_checks, jobs, metrics, orbit_camera, samplers
from mfsample import view_uncertainty as unc
from mfsample._pytree import replace
from mfsample.camera import Camera, InvalidCameraError
from mfsample.config_checks import ConfigError
from mfsample.data import (
  DatasetError,
  PointCloud,
  Views,
  export_blender,
  export_colmap,
  load_blender,
  load_colmap,
  load_llff,
  load_ply,
  poses_bounds_from_cameras,
)
from mfsample.data._io import read_image, read_json
from mfsample.groups import GROUPS
from mfsample.lighting import captures, lights
from mfsample.lighting import field as light_field
from mfsample.lighting import optimize as light_optimize
from mfsample.lighting import uncertainty as lu
from mfsample.lighting.field import init_relightable
from mfsample.model import init_model, model_from_mean, sample
from mfsample.planning import optimize as view_optimize
from mfsample.planning import poses, runner, tables
from mfsample.planning.config import validate as validate_planning
from mfsample.renderer import RenderSettings, render
from mfsample.renderer.budget import render_with_budget
from mfsample.samplers import SamplerSpec, sample_z
from mfsample.scenes import cache
from mfsample.selection import top_k
from mfsample.testing import random_gaussians
from mfsample.train import checkpoint as ckpt
from mfsample.train import experiment
from mfsample.train.config import validate as validate_training
from mfsample.train.experiment import train_and_evaluate
from mfsample.workdir import WorkdirError
from mfsample.your_data import sphere_candidates

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


# ====================================================================== Camera constructors

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


@pytest.mark.parametrize("name", BAD_POSES)
def test_camera_create_refuses(name):
  w2c, fx, fy, cx, cy, message = BAD_POSES[name]
  with pytest.raises(InvalidCameraError, match=message):
    Camera.create(w2c, fx, fy, cx, cy, 16, 16)


def test_camera_errors_name_the_batch_index():
  w2c = np.stack([W2C, W2C, np.diag([1.0, -1.0, 1.0, 1.0]) @ W2C])
  with pytest.raises(InvalidCameraError, match=r"world_to_camera\[2\] is a reflection.*fx\[1\]"):
    Camera.create(w2c, np.array([8.0, -1.0, 8.0]), 8.0, 8.0, 8.0, 16, 16)


@pytest.mark.parametrize("call, error, message", [
    (lambda: Camera.create(np.eye(3), 1, 1, 0, 0, 4, 4), ValueError, r"\[\.\.\., 4, 4\]"),
    (lambda: Camera.create(np.stack([W2C] * 2), np.ones(3), 1, 0, 0, 4, 4), ValueError,
     "fx of shape"),
    (lambda: Camera.create(W2C, 1, 1, 0, 0, 0, 4), ValueError, "width must be an integer"),
    (lambda: Camera.create(W2C, 1, 1, 0, 0, 4, 2.5), ValueError, "height must be an integer"),
    (lambda: Camera.create(W2C, 1, 1, 0, 0, True, 4), ValueError, "width must be an integer"),
    (lambda: Camera.look_at(np.array([NAN, 0, 1]), np.zeros(3), np.array([0, 0, 1.0]), 0.8,
                            8, 8), InvalidCameraError, "non-finite"),
    (lambda: Camera.look_at(np.array([3.0, 0, 1]), np.zeros(3), np.array([0, 0, 1.0]), 60.0,
                            8, 8), ValueError, r"fov_x = 60.0 must be in \(0, pi\) radians"),
    (lambda: Camera.look_at(np.array([3.0, 0, 1]), np.zeros(3), np.array([0, 0, 1.0]), 0.0,
                            8, 8), ValueError, r"fov_x = 0.0 must be in \(0, pi\)"),
    (lambda: Camera.from_blender(np.diag([2.0, 2, 2, 1]), 0.8, 8, 8), InvalidCameraError,
     "not rigid"),
    (lambda: Camera.from_blender(np.eye(4), "wide", 8, 8), ValueError,
     "camera_angle_x = 'wide' must be a number"),
    (lambda: Camera.look_at(np.zeros((2, 3)) + 3, np.zeros((3, 3)), np.array([0, 0, 1.0]), 0.8,
                            8, 8), ValueError, r"batch shapes of eye \[2, 3\], target \[3, 3\]"),
    (lambda: Camera.look_at(np.array([3.0, 0]), np.zeros(3), np.array([0, 0, 1.0]), 0.8, 8, 8),
     ValueError, r"eye must have shape \[\.\.\., 3\], got \[2\]"),
    (lambda: Camera.look_at(np.array([3.0, 0, 1]), np.zeros(3), np.array([0, NAN, 1.0]), 0.8,
                            8, 8), InvalidCameraError, r"up = \[0.0, nan, 1.0\] is not finite"),
    (lambda: Camera.look_at(np.array([3.0, 0, 1]), np.zeros(3), np.zeros(3), 0.8, 8, 8),
     InvalidCameraError, "up is a zero vector"),
    (lambda: Camera.from_blender(np.eye(4)[:, :3], 0.8, 8, 8), ValueError,
     r"c2w must have shape \[\.\.\., 4, 4\] or \[\.\.\., 3, 4\], got \[4, 3\]"),
])
def test_camera_constructor_table(call, error, message):
  with pytest.raises(error, match=message):
    call()


@pytest.mark.parametrize("eye, target", [
    ((0.0, 0.0, 3.0), (0.0, 0.0, 0.0)),  # looking along up: a fallback up vector
    ((1.0, 1.0, 1.0), (1.0, 1.0, 1.0)),  # eye == target: a fallback direction
])
def test_degenerate_look_at_is_a_valid_camera(eye, target):
  cam = Camera.look_at(np.array(eye), np.array(target), np.array([0.0, 0.0, 1.0]), 0.8, 8, 8)
  assert bool(cam.valid) and cam.problems() == []


def test_cameras_are_checkable_not_raising_under_jit_and_vmap():
  """Traced constructors check nothing (no error, no sync); `valid` flags the bad ones.
  (Under grad, tests/test_camera.py differentiates through look_at.)"""
  up = jnp.array([0.0, 0.0, 1.0])
  cams = Camera(jnp.stack([jnp.asarray(W2C, jnp.float32)] * 3),
                jnp.array([8.0, 0.0, 8.0]), jnp.full(3, 8.0), jnp.full(3, 8.0),
                jnp.full(3, 8.0), 16, 16)  # the raw constructor checks shapes only

  @jax.jit
  def flags_of(eyes, cameras):
    looked = jax.vmap(lambda e: Camera.look_at(e, jnp.zeros(3), up, 0.8, 8, 8).valid)(eyes)
    return looked, jax.vmap(lambda c: c.valid)(cameras)

  looked, given = flags_of(jnp.array([[3.0, 0.0, 1.0], [NAN, 0.0, 1.0]]), cams)
  np.testing.assert_array_equal(looked, [True, False])
  np.testing.assert_array_equal(given, [True, False, True])


# ====================================================================== render's inputs

SMALL = RenderSettings(max_intersections=2048, chunk_size=8, chunks_per_step=4)


def test_render_gives_nan_images_for_invalid_cameras():
  """Invalid cameras cannot raise under jit: their images are NaN (rgb, alpha, depth), so any
  finiteness check catches them, and the valid cameras of the batch are unaffected."""
  g = random_gaussians(24, sh_degree=0, seed=3, extent=0.5, scale_range=(0.1, 0.3),
                       opacity_range=(0.5, 0.9))
  names = ["valid", *BAD_POSES]
  rows = [(W2C, 8.0, 8.0, 8.0, 8.0)] + [BAD_POSES[n][:5] for n in BAD_POSES]
  cams = Camera(*(jnp.asarray(np.stack([np.asarray(r[i], np.float64) for r in rows]),
                              jnp.float32) for i in range(5)), 16, 16)
  out = jax.jit(jax.vmap(lambda c: render(g, c, settings=SMALL)))(cams)
  for i, name in enumerate(names):
    for what in ("rgb", "alpha", "depth"):
      image = np.asarray(getattr(out, what)[i])
      if name == "valid":
        assert np.all(np.isfinite(image)), what
      else:
        assert np.all(np.isnan(image)), (name, what)
  assert float(np.max(out.alpha[0])) > 0.1  # the valid camera sees the Gaussians


@pytest.mark.parametrize("call, error, message", [
    (lambda g, c: render(g, Camera.create(np.stack([W2C] * 2), 8, 8, 8, 8, 16, 16)),
     ValueError, "one camera"),
    (lambda g, c: render(g, W2C), TypeError, "mfsample.Camera"),
    (lambda g, c: render(g, c, features=jnp.ones((3, 2))), ValueError, "features must have"),
    (lambda g, c: render(replace(g, means=g.means[:, :2]), c), ValueError, "Gaussians.means"),
    (lambda g, c: render(replace(g, sh=jnp.zeros((4, 5, 3))), c), ValueError, "SH axis"),
    (lambda g, c: render(replace(g, mask=jnp.ones(4, jnp.int32)), c), ValueError,
     "mask must be boolean"),
    (lambda g, c: render(replace(g, opacities=jnp.ones(4, jnp.int32)), c), ValueError,
     "opacities must be floating"),
    (lambda g, c: render(g, c, background=jnp.ones(4)), ValueError,
     r"background must have shape \[3\] .*RGB colour\), got \[4\]"),
    (lambda g, c: render(g, c, features=jnp.ones((4, 2)), background=jnp.ones(3)), ValueError,
     r"background must have shape \[2\] \(one value per channel of features\)"),
    (lambda g, c: render(g, c, screen_offset=jnp.zeros((4, 3))), ValueError,
     r"screen_offset must have shape \[N=4, 2\], got \[4, 3\]"),
    (lambda g, c: RenderSettings(radius_sigma=NAN), ValueError,
     "RenderSettings.radius_sigma must be a finite number > 0.0, got nan"),
    (lambda g, c: RenderSettings(tile_size=2.5), ValueError,
     "RenderSettings.tile_size must be an integer >= 1, got 2.5"),
    (lambda g, c: render_with_budget(render, SMALL, g, c, max_budget=0), ValueError,
     "max_budget must be an integer >= 1, got 0"),
])
def test_render_input_table(call, error, message):
  g = random_gaussians(4, sh_degree=0, seed=0)
  with pytest.raises(error, match=message):
    call(g, orbit_camera(0.3, 0.4, width=16, height=16, distance=3.5))


# ====================================================================== init_model

SPEC = SamplerSpec(kind="lowrank", rank=2, groups=GROUPS, bounds=tuple((g, 1.0) for g in GROUPS))
SCALES = {g: 1e-3 for g in GROUPS}
POINTS = np.random.default_rng(0).uniform(-1, 1, (5, 3))


@pytest.mark.parametrize("changes, message", [
    ({"points": POINTS[:, :2]}, r"points must have shape \[N >= 1, 3\]"),
    ({"points": np.zeros((0, 3))}, r"points must have shape \[N >= 1, 3\]"),
    ({"points": np.where(np.arange(5)[:, None] == 3, NAN, POINTS)}, r"points\[3\] is not finite"),
    ({"capacity": 3}, "capacity 3 < number of points 5"),
    ({"sh_degree": 4}, "sh_degree must be an integer in 0..3"),
    ({"init_opacity": 1.0}, r"init_opacity must be a finite number in \(0.0, 1.0\), got 1.0"),
    ({"init_opacity": 0.0}, r"init_opacity must be a finite number in \(0.0, 1.0\), got 0.0"),
    ({"colors": np.ones((4, 3))}, r"colors must have shape \[N=5, 3\]"),
    ({"colors": np.full((5, 3), np.inf)}, r"colors\[0\] is not finite"),
    ({"init_scales": {"means": 1e-3}}, r"init_scales\['log_scales'\] must be a finite number"),
    ({"init_scales": {**SCALES, "quats": -1.0}}, r"init_scales\['quats'\]"),
    ({"colors": np.full((5, 3), 128, np.uint8)}, r"colors must be floats in \[0, 1\], got "
                                                 r"dtype uint8 \(for 8-bit colours pass "
                                                 r"colors / 255\)"),
    ({"colors": np.full((5, 3), 1.5)}, r"colors\[0\] = \[1.5, 1.5, 1.5\] is outside \[0, 1\]"),
    ({"points": np.full((5, 3), "1")}, "points must hold real numbers"),
    ({"capacity": 7.5}, "capacity must be an integer >= 1, got 7.5"),
    ({"init_opacity": NAN}, r"init_opacity must be a finite number in \(0.0, 1.0\), got nan"),
    ({"key": 0}, r"key must be one JAX PRNG key .*, got 0"),
    ({"key": jnp.zeros(3, jnp.uint32)}, r"key must be one JAX PRNG key .*shape \[3\]"),
])
def test_init_model_table(changes, message):
  kwargs = {"key": jax.random.PRNGKey(0), "points": POINTS, "spec": SPEC, "sh_degree": 1,
            "init_scales": SCALES, **changes}
  with pytest.raises(ValueError, match=message):
    init_model(**kwargs)


RELIGHTABLE = SamplerSpec(kind="lowrank", rank=2, groups=("transfer_dc",),
                          bounds=(("transfer_dc", 0.5),))


@pytest.mark.parametrize("changes, message", [
    ({"points": np.where(np.arange(5)[:, None] == 2, NAN, POINTS)}, r"points\[2\] is not finite"),
    ({"init_opacity": 1.0}, r"init_opacity must be a finite number in \(0.0, 1.0\), got 1.0"),
    ({"capacity": 3}, "capacity 3 < number of points 5"),
    ({"init_scales": {"transfer_dc": NAN}}, r"init_scales\['transfer_dc'\] must be a finite"),
    ({"key": 7}, "key must be one JAX PRNG key"),
    ({"light_coeffs": 5}, r"light_coeffs \(n\) must be one of \(1, 4, 9, 16\)"),
])
def test_init_relightable_table(changes, message):
  kwargs = {"key": jax.random.PRNGKey(0), "points": POINTS, "spec": RELIGHTABLE, "out_coeffs": 1,
            "light_coeffs": 4, "init_scales": {"transfer_dc": 0.1}, **changes}
  with pytest.raises(ValueError, match=message):
    init_relightable(**kwargs)


def test_model_from_a_mean_with_a_non_finite_row_is_refused():
  mean = {"means": POINTS.astype(np.float32), "log_scales": np.zeros((5, 3), np.float32),
          "quats": np.tile(np.float32([1, 0, 0, 0]), (5, 1)), "opacity_logits": np.zeros(5),
          "sh_dc": np.zeros((5, 3), np.float32)}
  mean["log_scales"][4, 1] = np.inf
  with pytest.raises(ValueError, match=r"mean\['log_scales'\]\[4\] is not finite"):
    model_from_mean(jax.random.PRNGKey(0), mean, spec=SPEC, init_scales=SCALES)


@pytest.mark.parametrize("kwargs, message", [
    ({"kind": "gaussian"}, "SamplerSpec.kind must be one of"),
    ({"kind": "lowrank", "rank": 0}, "rank must be an integer >= 1"),
    ({"groups": ("means", "colour")}, r"SamplerSpec.groups must be .* \('colour' is not one\)"),
    ({"groups": ("means",), "bounds": ()}, "no bound given for"),
    # A bound of NaN, -1 or 0 would clamp B_hat to NaN or 0 after the first training step.
    ({"groups": ("means",), "bounds": (("means", NAN),)},
     r"SamplerSpec.bounds\['means'\] must be a finite number > 0.0, got nan"),
    ({"groups": ("means",), "bounds": (("means", -1.0),)}, r"bounds\['means'\] .*got -1.0"),
    ({"groups": ("means",), "bounds": (("means", 0),)}, r"bounds\['means'\] .*got 0"),
    ({"groups": ("means",), "bounds": (("means", True),)}, r"bounds\['means'\] .*got True"),
    ({"rank": 2.5}, "SamplerSpec.rank must be an integer >= 1, got 2.5"),
    ({"kind": "diagonal", "rank": 0}, "SamplerSpec.rank must be an integer >= 1"),
    ({"groups": ("means", "means"), "bounds": (("means", 1.0),)}, "'means' repeats"),
    ({"groups": ("means",), "bounds": (("means", 1.0), ("means", 2.0))}, "two for 'means'"),
    ({"groups": ("means",), "bounds": (("colour", 1.0),)}, "names an unknown group 'colour'"),
    ({"groups": ["means"], "bounds": (("means", 1.0),)}, "SamplerSpec.groups must be a tuple"),
    ({"groups": ("means",), "bounds": {"means": 1.0}}, "SamplerSpec.bounds must be a tuple"),
])
def test_sampler_spec_table(kwargs, message):
  with pytest.raises(ValueError, match=message):
    SamplerSpec(**kwargs)


# ====================================================================== samplers, uncertainty


@pytest.mark.parametrize("call, message", [
    (lambda m: samplers.sobol_z(-1, 2, 0), "num must be an integer >= 0"),
    (lambda m: samplers.sobol_z(4, 2.5, 0), "dim must be an integer"),
    (lambda m: samplers.sobol_z(4, 30_000, 0), "exceeds the 21201 dimensions"),
    (lambda m: samplers.sobol_z(4, 2, 0, offset=-3), "offset must be an integer >= 0"),
    (lambda m: sample(m, jnp.zeros(3)), r"z must have shape \(2,\)"),
    (lambda m: sample_z(m, 0), "num_samples must be an integer >= 1"),
    (lambda m: unc.score_cameras(m, orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5),
                                 jnp.zeros((2, 2)), settings=SMALL),
     "batched over one axis"),
    (lambda m: samplers.sobol_z(4, 2, -1), "sobol_z: seed must be an integer in"),
    (lambda m: samplers.draw_z(m, 2, None, np.zeros((3, 2))),
     r"rows must have shape \[2, 2\] \(Sobol rows of the step\)"),
    (lambda m: sample_z(m, 2, seed=-1), r"seed must be an integer in \[0, "),
    (lambda m: sample_z(m, 2, seed=0.5), "seed must be an integer"),
    (lambda m: unc.pixel_variance(jnp.zeros((0, 4, 4, 3))), r"rgbs must have shape \[M >= 1, "),
    (lambda m: unc.score_cameras(m, _cams(), jnp.zeros((2, 2)), settings=SMALL, chunk_size=0),
     "chunk_size must be an integer >= 1, got 0"),
    (lambda m: unc.score_cameras(m, _cams(), jnp.zeros((2, 2)), settings=SMALL,
                                 num_devices=64), r"num_devices must be an integer in \[1, "),
    (lambda m: unc.score_cameras(m, _cams(), jnp.zeros((2, 2)), settings=SMALL, max_budget=0),
     "max_budget must be an integer >= 1"),
    (lambda m: unc.score_cameras(m, _cams(), jnp.zeros((2, 2)), settings=SMALL,
                                 background=(1.0, 1.0)), r"background must have shape \[3\]"),
    (lambda m: unc.uncertainty(m, orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5),
                               jnp.zeros((2, 2)),
                               background=np.array([0.0, NAN, 0.0])),
     r"background\[1\] is not finite"),
    (lambda m: unc.uncertainty(m, orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5),
                               jnp.zeros((2, 2)), num_devices=0),
     r"num_devices must be an integer in \[1, "),
])
def test_sampler_and_uncertainty_table(call, message):
  with pytest.raises(ValueError, match=message):
    call(random_model("lowrank", num=8))


def _cams(num=2):
  """`num` valid 8 x 8 cameras batched over one axis."""
  return Camera.create(np.stack([W2C] * num), 6.0, 6.0, 4.0, 4.0, 8, 8)


Z_BAD = {  # z of M = 2 low-rank samples (k = 2) with one bad row, and z with no sample
    "nan row": (np.array([[0.5, -0.5], [NAN, 0.1]], np.float32),
                r"z\[1\] \(sample 1\) is not finite \(1 of 2 samples"),
    "inf entry": (np.array([[0.5, np.inf], [0.3, 0.1]]), r"z\[0\] \(sample 0\) is not finite"),
    "no sample": (np.zeros((0, 2), np.float32), r"z must have shape \[M >= 1, 2\] .*got \[0, 2\]"),
    "wrong k": (np.zeros((2, 3), np.float32), r"z must have shape \[M >= 1, 2\] .*got \[2, 3\]"),
}


@pytest.mark.parametrize("case", Z_BAD)
@pytest.mark.parametrize("entry", ["uncertainty", "score_cameras", "light_uncertainty",
                                   "light_gram"])
def test_z_without_samples_or_with_a_non_finite_one_is_refused(case, entry):
  """A NaN row of z makes every Gaussian of its sample non-finite; the renderer culls them and
  U would come out finite and wrong. M = 0 would be a mean over nothing (NaN)."""
  z, message = Z_BAD[case]
  calls = {
      "uncertainty": lambda: unc.uncertainty(
          random_model("lowrank", num=8),
          orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5), z, settings=SMALL),
      "score_cameras": lambda: unc.score_cameras(random_model("lowrank", num=8), _cams(), z,
                                                 settings=SMALL),
      "light_uncertainty": lambda: lu.light_uncertainty(_relightable(), _cams(), z,
                                                        lights.uniform_light(4), settings=SMALL),
      "light_gram": lambda: lu.light_gram(_relightable(), _cams(), z, settings=SMALL),
  }
  with pytest.raises(ValueError, match=message):
    calls[entry]()


def _relightable():
  """An untrained relightable model (m = 1, n = 4) whose samples differ (B_hat over T)."""
  return init_relightable(jax.random.PRNGKey(0), POINTS * 0.3, spec=RELIGHTABLE, out_coeffs=1,
                          light_coeffs=4, init_scales={"transfer_dc": 0.2}, init_opacity=0.6)


def test_under_jit_a_non_finite_z_or_light_gives_nan_never_a_finite_u():
  """Traced values cannot raise: U, its map and U(xi) are NaN (before: finite for a NaN row of
  z, exactly 0 for a NaN light), and a finite input still gives a finite U > 0. A z on the
  device is not fetched to be checked by `uncertainty` (no sync per call): it gives NaN too;
  `score_cameras` synchronises anyway, so it checks it."""
  model, relit, camera = random_model("lowrank", num=8), _relightable(), _cams(1)
  u = jax.jit(lambda z: unc.uncertainty(model, camera[0], z, settings=SMALL))
  good = np.array([[0.5, -0.5], [-0.4, 0.3]], np.float32)
  assert float(u(good).value) > 0
  bad = u(good * np.array([[1.0], [NAN]], np.float32))
  assert np.isnan(float(bad.value)) and np.all(np.isnan(bad.pixel_map))
  on_device = jnp.asarray(good * np.array([[1.0], [NAN]], np.float32))
  assert np.isnan(float(unc.uncertainty(model, camera[0], on_device, settings=SMALL).value))
  with pytest.raises(ValueError, match=r"z\[1\] \(sample 1\) is not finite"):
    unc.score_cameras(model, _cams(), on_device, settings=SMALL, num_devices=1)
  xi = lights.uniform_light(4)
  u_light = jax.jit(lambda x: lu.light_uncertainty(relit, camera, good, x, settings=SMALL).value)
  assert float(u_light(jnp.asarray(xi, jnp.float32))) > 0
  assert np.isnan(float(u_light(jnp.asarray(xi * NAN, jnp.float32))))
  relit_image = jax.jit(lambda x: light_field.render_relit(
      relit.params.mean, relit.mask, x, camera[0], settings=SMALL).rgb)
  assert np.all(np.isnan(relit_image(jnp.full(4, NAN))))
  with pytest.raises(ValueError, match=r"xi has non-finite coefficients at \[0, 1, 2, 3\]"):
    light_field.render_relit(relit.params.mean, relit.mask, np.full(4, NAN), camera[0],
                             settings=SMALL)


def test_scores_of_invalid_cameras_are_nan_and_leave_the_others_alone():
  """One invalid candidate camera gives U = NaN for itself only (never a silent 0)."""
  model = random_model("lowrank", num=16)
  good = np.asarray(orbit_camera(0.3, 0.4, width=8, height=8, distance=3.0).world_to_camera,
                    np.float32)
  cams = Camera(jnp.asarray(np.stack([good, np.diag([1.0, 1, -1, 1]).astype(np.float32) @ good,
                                      good])),
                jnp.full(3, 6.0), jnp.full(3, 6.0), jnp.full(3, 4.0), jnp.full(3, 4.0), 8, 8)
  z = sample_z(model, 2)
  scores, _ = unc.score_cameras(model, cams, z, settings=SMALL, num_devices=1)
  values = np.asarray(scores.values)
  assert np.isnan(values[1]) and np.all(np.isfinite(values[[0, 2]]))
  assert values[0] == values[2] and values[0] > 0


def test_one_sample_is_allowed_and_gives_zero_uncertainty():
  z = sample_z(random_model("lowrank", num=16), 1)
  assert z.shape == (1, 2)
  rgbs = jnp.asarray(np.random.default_rng(0).uniform(size=(1, 4, 5, 3)), jnp.float32)
  assert not np.any(np.asarray(unc.pixel_variance(rgbs)))  # Eq. 10 with M = 1: exactly 0


# ====================================================================== lights, Q, metrics, views


@pytest.mark.parametrize("call, message", [
    (lambda: lights.on_sphere(np.array([NAN, 1.0, 0.0, 0.0])), r"xi\[0\] is not finite"),
    (lambda: lights.on_sphere(np.zeros(4)), "a zero light has no direction"),
    (lambda: lights.on_sphere(np.ones(4), norm=0.0), "norm must be a finite number > 0.0"),
    (lambda: lights.uniform_light(5), "an SH light has 1, 4, 9 or 16 coefficients, got 5"),
    (lambda: lights.held_out_lights(4, num_environments=1, num_random=-1, seed=0),
     "num_random must be an integer >= 0, got -1"),
    (lambda: lights.held_out_lights(4, num_environments=0, num_random=0, seed=0),
     "num_environments \\+ num_random >= 1"),
    (lambda: lights.held_out_lights(4, num_environments=1, num_random=1, seed=0, power=0.0),
     "power must be a finite number > 0.0"),
    (lambda: lights.held_out_lights(4, num_environments=1, num_random=1, seed=-2),
     "seed must be an integer in"),
    (lambda: lu.top_eigen(np.full((4, 4), NAN)), r"q\[0, 0\] is not finite"),
    (lambda: lu.top_eigen(np.ones((4, 3))), r"q must be a square \[n, n\] matrix, got shape "
                                            r"\[4, 3\]"),
    (lambda: lu.top_eigen(np.triu(np.ones((4, 4)))), r"q must be symmetric .*max \|Q - Q\^T\| = 1"),
    (lambda: lu.quadratic_u(np.eye(4), np.ones((2, 3))), r"lights must have shape \[\.\.\., 4\]"),
    (lambda: lu.quadratic_u(np.eye(4)[:3], np.ones(4)), "q must be a square"),
    (lambda: captures.capture(np.zeros((2, 4, 8, 8)), np.ones(4)),
     r"basis must have shape \[V, n, H, W, 3\]"),
    (lambda: light_optimize.AscentSettings(steps=2.5), "AscentSettings.steps must be an integer"),
    (lambda: light_optimize.AscentSettings(norm=NAN), "AscentSettings.norm must be a finite"),
    (lambda: light_field.radiance(_relightable().params.mean, np.ones(3), np.zeros((5, 3))),
     r"xi must be one SH light of 4 coefficients \(shape \[4\]\), got shape \[3\]"),
    (lambda: lu.light_uncertainty(_relightable(), _cams()[0], np.zeros((2, 2), np.float32),
                                  np.ones(4), settings=SMALL),
     r"cameras must be a Camera batched over one axis \[B\], got batch shape \(\)"),
])
def test_light_argument_table(call, message):
  with pytest.raises(ValueError, match=message):
    call()


IMAGE = np.random.default_rng(0).uniform(size=(12, 12, 3)).astype(np.float32)


@pytest.mark.parametrize("call, message", [
    (lambda: metrics.psnr(IMAGE, IMAGE[..., :1]),
     r"psnr: images a and b must have the same shape, got \[12, 12, 3\] and \[12, 12, 1\]"),
    (lambda: metrics.mse(IMAGE[None], IMAGE), "mse: images a and b must have the same shape"),
    (lambda: metrics.ssim(IMAGE, IMAGE[:11]), "ssim: images a and b must have the same shape"),
    (lambda: metrics.psnr(IMAGE, (IMAGE * 255).astype(np.uint8)),
     "same kind of dtype, got float32 and uint8"),
    (lambda: metrics.psnr(IMAGE[0], IMAGE[0]), r"must have shape \[\.\.\., H, W, C\]"),
    (lambda: metrics.make_lpips("vgg"), "net must be one of"),
])
def test_metric_argument_table(call, message):
  with pytest.raises(ValueError, match=message):
    call()


def test_integer_images_are_compared_in_floats_with_their_dtype_peak():
  """uint8 arithmetic wraps (0 - 1 = 255) and a peak of 1 for 0..255 values gives about
  -40 dB: integer images are compared as floats, with max_val = the dtype's maximum."""
  a = np.zeros((4, 4, 3), np.uint8)
  b = np.full((4, 4, 3), 255, np.uint8)
  assert float(metrics.mse(a, b)) == 255.0 ** 2
  assert float(metrics.mse(b, a)) == 255.0 ** 2  # not (0 - 255) mod 256
  q = np.round(IMAGE * 255).astype(np.uint8)
  noisy = np.clip(q.astype(int) + np.random.default_rng(1).integers(-3, 4, q.shape), 0,
                  255).astype(np.uint8)
  as_float = metrics.psnr(q / 255.0, noisy / 255.0)
  np.testing.assert_allclose(float(metrics.psnr(q, noisy)), float(as_float), rtol=1e-5)
  assert 30 < float(metrics.psnr(q, noisy)) < 60
  np.testing.assert_allclose(float(metrics.ssim(q, noisy)),
                             float(metrics.ssim(q / 255.0, noisy / 255.0)), rtol=1e-5)
  # An explicit peak is taken as given.
  np.testing.assert_allclose(float(metrics.psnr(q, noisy, max_val=1.0)),
                             float(metrics.psnr(q, noisy)) - 20 * np.log10(255), rtol=1e-5)


@pytest.mark.parametrize("call, message", [
    (lambda: poses.SphereSpec(radius=NAN), "SphereSpec.radius must be a finite number > 0.0"),
    (lambda: poses.SphereSpec(center=(0.0, 0.0)), "SphereSpec.center must be 3 numbers"),
    (lambda: poses.SphereSpec(fov_x=40.0), r"SphereSpec.fov_x must be a finite number in "
                                           r"\(0.0, 3.14"),
    (lambda: poses.SphereSpec(width=0), "SphereSpec.width must be an integer >= 1"),
    (lambda: poses.spherical_camera(jnp.zeros(3), poses.SphereSpec()),
     r"uv must have shape \[\.\.\., 2\], got \[3\]"),
    (lambda: poses.perturb_camera(_cams(1)[0], jnp.zeros(5)),
     r"xi must have shape \[6\] \(one tangent vector per camera\), got \[5\]"),
    (lambda: poses.perturb_camera(_cams(2), jnp.zeros(6)), r"xi must have shape \[2, 6\]"),
    (lambda: poses.se3_exp(jnp.zeros((2, 5))), r"xi must have shape \[\.\.\., 6\]"),
    (lambda: poses.camera_to_uv(_cams(2), center=(0.0, NAN, 0.0)), r"center\[1\] is not finite"),
    (lambda: view_optimize.OptimizeSettings(steps=2.5), "OptimizeSettings.steps must be an "
                                                        "integer >= 1, got 2.5"),
    (lambda: view_optimize.OptimizeSettings(lr=NAN), "OptimizeSettings.lr must be a finite"),
    (lambda: view_optimize.OptimizeSettings(resample_z="yes"), "resample_z must be True or False"),
    (lambda: view_optimize.optimize_spherical(random_model("lowrank", num=8), [NAN, 0.3],
                                              np.zeros((2, 2), np.float32),
                                              sphere=poses.SphereSpec()),
     r"uv0\[0\] is not finite"),
    (lambda: view_optimize.optimize_se3(random_model("lowrank", num=8), _cams(2),
                                        np.zeros((2, 2), np.float32)),
     "camera0 must be one unbatched"),
    (lambda: view_optimize.optimize_se3(random_model("lowrank", num=8), _cams(1)[0],
                                        np.full((2, 2), NAN, np.float32)),
     r"z\[0\] \(sample 0\) is not finite"),
    (lambda: top_k([0.3, 0.1], -1), "k must be an integer >= 0, got -1"),
    (lambda: top_k([0.3, NAN, 0.2], 1), r"values\[1\] is NaN \(1 of 3\)"),
    (lambda: top_k(np.zeros((2, 2)), 1), r"values must have shape \[B\], got \[2, 2\]"),
    (lambda: sphere_candidates(_cams(2), (0.0, 0.0, NAN), 4), r"center\[2\] is not finite"),
    (lambda: sphere_candidates(_cams(2), (0.0, 0.0, 0.0), 0), "num must be an integer >= 1"),
])
def test_planning_and_next_view_argument_table(call, message):
  with pytest.raises(ValueError, match=message):
    call()


def test_top_k_beyond_the_count_returns_all_in_order():
  np.testing.assert_array_equal(top_k([0.1, 0.4, 0.2], 5), [1, 2, 0])
  assert top_k([0.1, 0.4], 0).size == 0


# ====================================================================== training configs

TRAINING_BAD = [  # (field, value, message fragment)
    ("seed", -1, r"config.seed = -1: must be an integer in \[0, 2147483647\]"),
    ("data.kind", "colmapp", "config.data.kind = 'colmapp': must be one of"),
    ("data.downscale", 0, "config.data.downscale = 0: must be an integer >= 1"),
    ("data.background", (1.0, 1.0), "config.data.background = .*: must be 3 finite numbers"),
    ("data.background", (1.0, NAN, 1.0), "must be 3 finite numbers in"),
    ("data.init_bounds", (1.3, -1.3), "strictly increasing"),
    ("data.extent", 0.0, "config.data.extent = 0.0: must be a finite number > 0.0"),
    ("data.synthetic.sh_degree", 4, r"must be an integer in \[0, 3\]"),
    ("model.sh_degree", 5, r"config.model.sh_degree = 5: must be an integer in \[0, 3\]"),
    ("model.init_points", 0, "config.model.init_points = 0: must be an integer >= 1"),
    ("model.init_opacity", 1.0, "config.model.init_opacity = 1.0: must be a finite number"),
    ("sampler.kind", "gauss", "config.sampler.kind = 'gauss'"),
    ("sampler.rank", 0, "config.sampler.rank = 0: must be an integer >= 1"),
    ("sampler.groups", ("means", "means"), "'means' repeats"),
    ("sampler.groups", ("means", "colour"), "'colour' is not one"),
    ("sampler.num_samples", 0, "config.sampler.num_samples = 0"),
    ("sampler.z", "halton", "config.sampler.z = 'halton'"),
    ("sampler.bounds.means", 0.0, "config.sampler.bounds.means = 0.0"),
    ("sampler.lr.quats", -1e-4, "config.sampler.lr.quats = -0.0001"),
    ("loss.ssim_weight", 1.5, r"config.loss.ssim_weight = 1.5: must be a finite number in \[0"),
    ("loss.volume_every", 0, "config.loss.volume_every = 0"),
    ("optim.position_lr_final", 0.0, "config.optim.position_lr_final = 0.0"),
    ("densify.every", 0, "config.densify.every = 0: must be an integer >= 1"),
    ("densify.opacity_reset_every", 0, "config.densify.opacity_reset_every = 0"),
    ("densify.min_opacity", 1.0, "config.densify.min_opacity = 1.0"),
    ("render.max_intersections", 0, "config.render.max_intersections = 0"),
    ("render.max_budget", 1024, "config.render.max_budget = 1024: must be an integer >= "
                                "max_intersections = 4096"),
    ("render.tile_size", 0, "config.render.tile_size = 0"),
    ("render.chunks_per_step", 0, "config.render.chunks_per_step = 0"),
    ("train.num_steps", 0, "config.train.num_steps = 0: must be an integer >= 1"),
    ("train.checkpoint_every", 0, "config.train.checkpoint_every = 0: must be an integer >= 1"),
    ("train.keep_checkpoints", -1, "config.train.keep_checkpoints = -1: must be an integer"),
    ("train.keep_checkpoints", 0, "config.train.keep_checkpoints = 0"),
    ("train.log_every", 0, "config.train.log_every = 0"),
    ("train.num_steps", None, "config.train.num_steps = None: must be an integer"),
    ("train.progress", None, "config.train.progress = None: must be True or False"),
    ("eval.lpips_net", "vgg", "config.eval.lpips_net = 'vgg'"),
    ("eval.uncertainty_samples", 1, "config.eval.uncertainty_samples = 1: must be 0"),
    ("eval.save_images", -1, "config.eval.save_images = -1"),
]


@pytest.mark.parametrize("field, value, message", TRAINING_BAD)
def test_training_config_table(field, value, message):
  config = tiny_config("lowrank")
  *parents, leaf = field.split(".")
  node = config
  for p in parents:
    node = node[p]
  with config.unlocked():
    node[leaf] = value
  with pytest.raises(ConfigError, match=message):
    validate_training(config)


@pytest.mark.parametrize("field, value", [("train.num_steps", 10.5), ("train.progress", "yes"),
                                          ("sampler.rank", "2")])
def test_config_dicts_refuse_another_type_on_assignment(field, value):
  config = tiny_config("lowrank")  # (and so does the command line: --config.train.num_steps)
  with pytest.raises(TypeError, match=f"Could not override field '{field.split('.')[-1]}'"):
    _set(config, field, value)


@pytest.mark.parametrize("override, error, message", [
    ("--config.train.nonexistent=3", AttributeError, "'nonexistent'"),
    ("--config.trian.num_steps=3", KeyError, "Did you mean \"train\" instead of \"trian\""),
])
def test_unknown_fields_on_the_command_line_are_refused_by_name(override, error, message):
  """ml_collections refuses a field the config lacks while absl parses the command line,
  before an experiment's main (and its validation) runs, naming the field; a close match is
  suggested."""
  config_file = os.path.join(os.path.dirname(__file__), "..", "configs", "train.py")
  argv = ["prog", f"--config={config_file}:tiny", override]
  fv = flags.FlagValues()
  config_flags.DEFINE_config_file("config", None, "", flag_values=fv, lock_config=True,
                                  sys_argv=argv)
  with pytest.raises(error, match=message):
    fv(argv)


def test_train_refuses_a_bad_config_before_any_step(tiny_dataset, tmp_path):
  # Not a ZeroDivisionError after the first step, nor every checkpoint deleted as written.
  for field, value in (("checkpoint_every", 0), ("keep_checkpoints", -1)):
    config = tiny_config("lowrank", **{f"train.{field}": value})
    with pytest.raises(ConfigError, match=f"config.train.{field}"):
      validate_training(config)
    with pytest.raises(ValueError, match=f"{field} must be an integer >= 1"):
      train_with(tiny_config("lowrank"), tiny_dataset, checkpoint_dir=str(tmp_path / "c"),
                 **{field: value})
  assert not (tmp_path / "c").exists()
  for keep in (0, -1, True, 1.5):
    with pytest.raises(ValueError, match="keep = .*: must be an integer >= 1"):
      ckpt.save_checkpoint(str(tmp_path / "c"), {"a": jnp.zeros(2)}, {"step": 1}, keep=keep)


# ====================================================================== train_and_evaluate


def _write_workdir(workdir, config_text, checkpoint=True):
  os.makedirs(os.path.join(workdir, "checkpoints"), exist_ok=True)
  with open(os.path.join(workdir, "config.json"), "w") as f:
    f.write(config_text)
  if checkpoint:
    with open(os.path.join(workdir, "checkpoints", "ckpt_00000008.npz"), "wb") as f:
      f.write(b"stands for a checkpoint")


def _tree_files(root):
  return sorted((os.path.relpath(os.path.join(d, n), root), os.path.getmtime(os.path.join(d, n)))
                for d, _, names in os.walk(root) for n in names)


@pytest.mark.parametrize("case, error, message", [
    ("different config", WorkdirError,
     r"holds training results made with a different config \(differences: "
     r"loss.ssim_weight, sampler.rank\)"),
    ("empty config.json", WorkdirError, r"config.json is unreadable"),
    ("config.json not an object", WorkdirError, "does not hold a JSON object"),
    ("invalid config", ConfigError, "config.train.checkpoint_every = 0"),
    ("mistyped --config path", OSError, "Failed loading config file"),
    ("missing dataset", FileNotFoundError, "No NeRF Synthetic scene"),
])
def test_train_and_evaluate_writes_nothing_for_a_bad_call(tmp_path, case, error, message):
  """Each case leaves the workdir exactly as it was: config.json neither overwritten nor
  emptied, no results of two configs mixed."""
  workdir = str(tmp_path / "run")
  config = tiny_config("lowrank")
  stored = tiny_config("lowrank")
  stored.loss.ssim_weight = 0.5
  stored.sampler.rank = 3
  text = {"different config": stored.to_json_best_effort(indent=2),
          "empty config.json": "", "config.json not an object": "[1, 2]"}.get(
              case, config.to_json_best_effort(indent=2))
  _write_workdir(workdir, text)
  if case == "invalid config":
    config.train.checkpoint_every = 0
  elif case == "mistyped --config path":
    argv = ["prog", f"--config={tmp_path / 'configs' / 'trian.py'}"]
    fv = flags.FlagValues()
    config_flags.DEFINE_config_file("config", None, "", flag_values=fv, lock_config=True,
                                    sys_argv=argv)
    fv(argv)
    config = fv.config  # absl defers the error to the first use
  elif case == "missing dataset":
    config.data.kind = "blender"
    config.data.path = str(tmp_path / "nowhere")
    shutil.rmtree(workdir)
  before = _tree_files(tmp_path)
  with pytest.raises(error, match=message):
    train_and_evaluate(config, workdir)
  assert _tree_files(tmp_path) == before


def test_the_workdir_guard_lets_speed_and_bookkeeping_fields_differ(tmp_path):
  config = tiny_config("lowrank")
  _write_workdir(str(tmp_path), config.to_json_best_effort(indent=2))
  config.render.chunks_per_step = 64
  config.train.checkpoint_every = 7
  config.train.keep_checkpoints = 5
  config.train.progress = True
  jobs.check_workdir(experiment.JOB, config, str(tmp_path))  # the same results, written otherwise
  config.train.log_every = 3
  with pytest.raises(WorkdirError, match=r"differences: train.log_every\)"):
    jobs.check_workdir(experiment.JOB, config, str(tmp_path))
  # A config.json with nothing computed from it is simply replaced.
  os.remove(tmp_path / "checkpoints" / "ckpt_00000008.npz")
  jobs.check_workdir(experiment.JOB, config, str(tmp_path))


# ====================================================================== checkpoints


@pytest.fixture(scope="module")
def straight(tiny_dataset):
  """The uninterrupted 16-step run of `resume_config` (densification, budget growth)."""
  return train_with(resume_config(), tiny_dataset)


def _assert_same_run(a, b, stopped_at=None):
  """Equal states, and equal logs (`train(stop_at=n)` also logs step n, which a checkpoint
  written at n keeps)."""
  for x, y in zip(jax.tree.leaves(a.state), jax.tree.leaves(b.state), strict=True):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
  strip = lambda h: [{k: v for k, v in e.items() if k != "seconds"} for e in h]
  assert strip(a.history) == [e for e in strip(b.history) if e["step"] != stopped_at
                              or stopped_at in [f["step"] for f in a.history]]


@pytest.mark.slow
@pytest.mark.parametrize("kill_at", [5, 8, 13])
def test_training_killed_at_several_points_resumes_bit_identically(tiny_dataset, straight,
                                                                   tmp_path, kill_at):
  """Killed before the first checkpoint (5), right after one (8), after densification (13):
  the resumed run equals the uninterrupted one, log included."""
  config, d = resume_config(), str(tmp_path / "checkpoints")
  train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=8, stop_at=kill_at)
  saved = [os.path.basename(p) for p in ckpt.list_checkpoints(d)]
  assert saved == ([] if kill_at < 8 else ["ckpt_00000008.npz"])
  resumed = train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=8)
  _assert_same_run(straight, resumed, stopped_at=kill_at)


@pytest.mark.slow
def test_a_corrupt_latest_checkpoint_falls_back_to_the_newest_intact_one(tiny_dataset, straight,
                                                                          tmp_path):
  config, d = resume_config(), str(tmp_path / "checkpoints")
  train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=8)
  latest = ckpt.list_checkpoints(d)[-1]
  assert latest.endswith("ckpt_00000016.npz")
  with open(latest, "r+b") as f:  # truncated, as by a full disk or an interrupted copy
    f.truncate(os.path.getsize(latest) // 2)
  with pytest.warns(UserWarning, match=r"ckpt_00000016.npz is unreadable \(BadZipFile"):
    resumed = train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=8)
  _assert_same_run(straight, resumed)  # re-ran 8 -> 16 from the intact checkpoint
  assert ckpt.read_meta(latest)["step"] == 16  # and replaced the corrupt file


@pytest.mark.parametrize("damage, message", [
    (lambda p: open(p, "wb").write(b"garbage"), r"unreadable \(ValueError"),  # not a zip
    (lambda p: open(p, "r+b").truncate(100), "BadZipFile"),
    (lambda p: np.savez(p, a=np.zeros(2)), r"KeyError.*__meta__"),
    (lambda p: np.savez(p, __meta__=np.asarray("{not json")), "JSONDecodeError"),
    (lambda p: np.savez(p, __meta__=np.asarray(json.dumps({"no": "step"}))), "no valid metadata"),
])
def test_unreadable_checkpoints_are_named(tmp_path, damage, message):
  path = ckpt.save_checkpoint(str(tmp_path), {"a": jnp.zeros(2)}, {"step": 3})
  damage(path)
  with pytest.raises(ckpt.CorruptCheckpointError, match=rf"ckpt_00000003.npz.*{message}"):
    ckpt.read_meta(path)


def test_without_an_intact_checkpoint_resuming_is_refused(tiny_dataset, tmp_path):
  config, d = resume_config(), tmp_path / "checkpoints"
  d.mkdir()
  for step in (8, 16):
    (d / f"ckpt_{step:08d}.npz").write_bytes(b"")
  with pytest.warns(UserWarning), pytest.raises(
      ckpt.CorruptCheckpointError, match=r"no readable checkpoint.*ckpt_00000016.*ckpt_00000008"):
    train_with(config, tiny_dataset, checkpoint_dir=str(d))


def test_checkpoints_of_another_config_are_refused(tiny_dataset, tmp_path):
  config, d = resume_config(), str(tmp_path / "checkpoints")
  train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=1, stop_at=1)
  other = resume_config()
  other.loss.ssim_weight = 0.5
  with pytest.raises(WorkdirError, match=r"different training settings \(differences: "
                                         r"loss.ssim_weight\)"):
    train_with(other, tiny_dataset, checkpoint_dir=d)
  other = resume_config()
  other.seed = 1
  with pytest.raises(WorkdirError, match="seed 0, this run has seed 1"):
    train_with(other, tiny_dataset, checkpoint_dir=d)
  other = resume_config()
  other.sampler.rank = 3
  with pytest.raises(WorkdirError, match="another sampler"):
    train_with(other, tiny_dataset, checkpoint_dir=d)


@pytest.mark.slow
def test_training_killed_between_its_result_files_resumes(tiny_dataset, straight, tmp_path,
                                                          monkeypatch):
  """Killed after the last checkpoint but before metrics.json: the rerun trains nothing and
  equals the uninterrupted run. Killed while metrics.json is being replaced: the previous
  file stays whole and no temporary is left."""
  from mfsample.train import evaluate as eval_lib

  config, workdir = resume_config(), str(tmp_path / "run")
  config.eval.uncertainty_samples = 0  # (test_train covers the maps: fewer compilations here)
  config.eval.save_images = 1
  evaluate = eval_lib.evaluate

  def killed(*args, **kwargs):
    raise KeyboardInterrupt("killed")

  monkeypatch.setattr(eval_lib, "evaluate", killed)
  with pytest.raises(KeyboardInterrupt):
    train_and_evaluate(config, workdir)
  assert os.path.exists(os.path.join(workdir, "train_log.json"))
  assert not os.path.exists(os.path.join(workdir, "metrics.json"))
  monkeypatch.setattr(eval_lib, "evaluate", evaluate)
  resumed = train_and_evaluate(config, workdir)
  for x, y in zip(jax.tree.leaves(straight.state), jax.tree.leaves(resumed), strict=True):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
  metrics_path = os.path.join(workdir, "metrics.json")
  metrics = open(metrics_path).read()
  assert json.loads(metrics)["steps"] == 16

  replace = os.replace

  def dies_on_metrics(src, dst):
    if str(dst).endswith("metrics.json"):
      raise KeyboardInterrupt("killed")
    return replace(src, dst)

  monkeypatch.setattr(os, "replace", dies_on_metrics)
  with pytest.raises(KeyboardInterrupt):
    train_and_evaluate(config, workdir)
  assert open(metrics_path).read() == metrics  # the previous file, whole
  assert not [n for n in os.listdir(workdir) if ".tmp" in n]


# ====================================================================== planning configs

PLANNING_BAD = [  # (field, value, message fragment)
    ("seeds", (0, 1, 0), r"config.seeds = \(0, 1, 0\): repeats 0; each must appear once"),
    ("seeds", (), "must hold at least 1 item"),
    ("seeds", (-1,), "-1 is not an integer >= 0"),
    ("strategies", ("random", "random"), "repeats 'random'"),
    ("strategies", ("random", "best"), "'best' is not one of"),
    ("eval_views", (2, 5), r"config.eval_views = \(2, 5\): every count must be <= "
                           "config.max_views = 3"),
    ("eval_views", (2, 2), "repeats 2"),
    ("eval_views", (0, 3), "0 is not an integer >= 1"),
    ("max_views", 9, "config.max_views = 9 must be <= config.data.num_train = 8"),
    ("initial_view", 8, "config.initial_view = 8 must be < config.data.num_train = 8"),
    ("paired_references", ("farthest", "nope"), "'nope' is not one of"),
    ("data.kind", "nerf", "config.data.kind = 'nerf'"),
    ("data.num_train", 0, "config.data.num_train = 0"),
    ("data.synthetic.v_range", (0.6, 0.1), "strictly increasing"),
    ("data.synthetic.distance", 0.4, r"config.data.synthetic.distance = 0.4: must be a finite "
                                     r"number > 0.5"),
    ("rounds.steps", 0, "config.rounds.steps = 0"),
    ("rounds.warm_start", None, "config.rounds.warm_start = None: must be True or False"),
    ("round_train.train.log_every", 0, "config.round_train.train.log_every = 0"),
    ("final_train.train.num_steps", -5, "config.final_train.train.num_steps = -5"),
    ("final_train.sampler.rank", 0, "config.final_train.sampler.rank = 0"),
    ("strategy.ours.select_samples", 1, "config.strategy.ours.select_samples = 1: must be an "
                                        "integer >= 2"),
    ("strategy.optimize.samples", 1, "config.strategy.optimize.samples = 1"),
    ("strategy.optimize.sampler", "gauss", "config.strategy.optimize.sampler = 'gauss'"),
    ("strategy.fisher.groups", ("means", "means"), "'means' repeats"),
    ("strategy.activenerf.prior_var", 0.0, "config.strategy.activenerf.prior_var = 0.0"),
    ("strategy.acp.resolution", 0, "config.strategy.acp.resolution = 0"),
    ("figures.landscape_u", 0, "config.figures.landscape_u = 0"),
]


def _set(config, field, value):
  *parents, leaf = field.split(".")
  node = config
  for p in parents:
    node = node[p]
  with config.unlocked():
    node[leaf] = value


@pytest.mark.parametrize("field, value, message", PLANNING_BAD)
def test_planning_config_table(field, value, message):
  config = camera_planning.get_config("tiny")
  _set(config, field, value)
  with pytest.raises(ConfigError, match=message):
    validate_planning(config)


def test_warm_start_with_densifying_rounds_is_refused_on_entry():
  config = camera_planning.get_config("tiny")
  config.rounds.warm_start = True
  config.round_train.densify.start = 50
  with pytest.raises(ConfigError, match="cannot densify: config.round_train.densify.start"):
    validate_planning(config)


def test_run_camera_planning_writes_nothing_for_a_bad_config(tmp_path):
  config = camera_planning.get_config("tiny")
  config.seeds = (0, 0)
  with pytest.raises(ConfigError, match="repeats 0"):
    runner.run_camera_planning(config, str(tmp_path / "run"))
  assert not (tmp_path / "run").exists()


def _record(strategy, seed, psnr):
  return {"strategy": strategy, "label": strategy, "seed": seed, "seconds": 1.0,
          "round_seconds": [0.0, 1.0], "optimisation": [],
          "metrics": {"3": {"psnr": psnr, "ssim": 0.5, "lpips": None}}}


def test_tables_count_a_repeated_run_once():
  records = [_record("random", 0, 20.0), _record("random", 1, 22.0), _record("random", 0, 20.0),
             _record("farthest", 0, 21.0), _record("farthest", 1, 21.0)]
  summary = tables.summarise(records, (3,))
  assert summary["random"]["3"]["psnr"]["values"] == [20.0, 22.0]
  assert tables.seconds_summary(records)["random"]["runs"] == 2
  paired = tables.paired_differences(records, (3,), "farthest")
  assert paired["random"]["3"]["seeds"] == [0, 1]
  with pytest.raises(ValueError, match="two different records of strategy 'random', seed 0"):
    tables.summarise(records + [_record("random", 0, 25.0)], (3,))


# ====================================================================== planning resume


def _planning_config():
  config = camera_planning.get_config("tiny")
  config.strategies = ("random", "farthest")
  config.figures.enabled = False
  return config


def _comparable(results):
  """results.json less wall-clock, as JSON text."""
  drop = {"seconds", "round_seconds", "seconds_this_call", "run_seconds"}

  def strip(x):
    if isinstance(x, dict):
      return {k: strip(v) for k, v in x.items() if k not in drop}
    if isinstance(x, (list, tuple)):
      return [strip(v) for v in x]
    return x

  return json.dumps(strip(results), sort_keys=True)


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
  """An uninterrupted tiny planning run (two strategies, one seed) and its workdir."""
  workdir = tmp_path_factory.mktemp("planned")
  return runner.run_camera_planning(_planning_config(), str(workdir)), workdir


@pytest.mark.slow
def test_planning_killed_during_a_run_resumes_to_the_same_results(planned, tmp_path,
                                                                  monkeypatch):
  reference, _ = planned
  plan_views, calls = runner.plan_views, []

  def killed_in_second_run(*args, **kwargs):
    calls.append(args[0].name)
    if len(calls) == 2:
      raise KeyboardInterrupt("killed")
    return plan_views(*args, **kwargs)

  monkeypatch.setattr(runner, "plan_views", killed_in_second_run)
  with pytest.raises(KeyboardInterrupt):
    runner.run_camera_planning(_planning_config(), str(tmp_path))
  assert sorted(os.listdir(tmp_path / "runs")) == ["random-seed0.json"]
  assert not (tmp_path / "results.json").exists()
  monkeypatch.setattr(runner, "plan_views", plan_views)
  resumed = runner.run_camera_planning(_planning_config(), str(tmp_path))
  assert _comparable(resumed) == _comparable(reference)


@pytest.mark.slow
def test_planning_killed_between_its_result_files_resumes(planned, tmp_path, monkeypatch):
  """Runs written, results.json / table.md not (or killed while being replaced)."""
  reference, workdir = planned
  shutil.copytree(workdir, tmp_path / "run")
  (tmp_path / "run" / "results.json").unlink()
  (tmp_path / "run" / "table.md").write_text("an older table")
  replace = os.replace

  def dies_on_table(src, dst):
    if dst.endswith("table.md"):
      raise KeyboardInterrupt("killed")
    return replace(src, dst)

  monkeypatch.setattr(os, "replace", dies_on_table)
  with pytest.raises(KeyboardInterrupt):
    runner.run_camera_planning(_planning_config(), str(tmp_path / "run"))
  monkeypatch.setattr(os, "replace", replace)
  assert (tmp_path / "run" / "table.md").read_text() == "an older table"  # never truncated
  assert not [n for n in os.listdir(tmp_path / "run") if ".tmp" in n]
  resumed = runner.run_camera_planning(_planning_config(), str(tmp_path / "run"))
  assert _comparable(resumed) == _comparable(reference)
  assert (tmp_path / "run" / "table.md").read_text() == (workdir / "table.md").read_text()


@pytest.mark.slow
def test_a_damaged_run_record_is_reported_and_computed_again(planned, tmp_path):
  reference, workdir = planned
  shutil.copytree(workdir, tmp_path / "run")
  record = tmp_path / "run" / "runs" / "farthest-seed0.json"
  record.write_text(record.read_text()[:100])  # truncated by a crash of another tool
  with pytest.warns(UserWarning, match=r"farthest-seed0\.json is damaged"):
    resumed = runner.run_camera_planning(_planning_config(), str(tmp_path / "run"))
  assert _comparable(resumed) == _comparable(reference)
  assert json.loads(record.read_text())["strategy"] == "farthest"


def test_planning_refuses_a_workdir_of_another_protocol(planned, tmp_path):
  _, workdir = planned
  shutil.copytree(workdir, tmp_path / "run")
  before = _tree_files(tmp_path)
  config = _planning_config()
  config.final_train.train.num_steps = 13
  with pytest.raises(WorkdirError, match=r"differences: final_train.train.num_steps\)"):
    runner.run_camera_planning(config, str(tmp_path / "run"))
  (tmp_path / "run" / "config.json").write_text("")  # unknown protocol: refused too
  before = _tree_files(tmp_path)
  with pytest.raises(WorkdirError, match="config.json is unreadable"):
    runner.run_camera_planning(_planning_config(), str(tmp_path / "run"))
  assert _tree_files(tmp_path) == before


# ====================================================================== loaders


def _png(path, array, bit_depth=16):
  """Writes a non-palette PNG of [H, W, C] unsigned integers (any bit depth PNG allows)."""
  h, w, c = array.shape
  colour_type = {1: 0, 2: 4, 3: 2, 4: 6}[c]
  dtype = ">u2" if bit_depth == 16 else ">u1"
  raw = b"".join(b"\x00" + array[i].astype(dtype).tobytes() for i in range(h))

  def chunk(tag, data):
    return (struct.pack(">I", len(data)) + tag + data
            + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))

  header = struct.pack(">IIBBBBB", w, h, bit_depth, colour_type, 0, 0, 0)
  with open(path, "wb") as f:
    f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw))
            + chunk(b"IEND", b""))


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_16_bit_pngs_are_read_at_full_precision(tmp_path, channels):
  values = np.random.default_rng(channels).integers(0, 65536, (3, 5, channels), np.uint16)
  _png(tmp_path / "x.png", values)
  color, alpha = read_image(tmp_path / "x.png")
  expected = values.astype(np.float32) / 65535.0
  want_color = expected[..., :3] if channels >= 3 else np.repeat(expected[..., :1], 3, -1)
  np.testing.assert_array_equal(color, want_color)  # not rounded to 8 bits
  if channels in (2, 4):
    np.testing.assert_array_equal(alpha, expected[..., -1])
  else:
    assert alpha is None


def _pillow(tmp_path, name, make):
  path = tmp_path / name
  make().save(path)
  return path


@pytest.mark.parametrize("name, make, color, alpha", [
    ("palette.png", lambda: Image.fromarray(np.array([[0, 255]], np.uint8)).convert("P"),
     [[0.0] * 3, [1.0] * 3], None),
    ("bilevel.png", lambda: Image.fromarray(np.array([[False, True]])), [[0.0] * 3, [1.0] * 3],
     None),
    ("cmyk.jpg", lambda: Image.new("CMYK", (2, 1), (0, 0, 0, 0)), [[1.0] * 3] * 2, None),
    ("grey_alpha.png", lambda: Image.fromarray(np.array([[[51, 255], [102, 0]]], np.uint8), "LA"),
     [[0.2] * 3, [0.4] * 3], [1.0, 0.0]),
])
def test_image_modes_are_decoded_not_misread(tmp_path, name, make, color, alpha):
  c, a = read_image(_pillow(tmp_path, name, make))
  np.testing.assert_allclose(c[0], color, atol=2 / 255)  # a CMYK file is RGB, not RGBA
  if alpha is None:
    assert a is None
  else:
    np.testing.assert_allclose(a[0], alpha, atol=1e-6)


@pytest.mark.parametrize("content", [b"", b"not an image", b"\x89PNG\r\n\x1a\n" + b"\x00" * 30])
def test_unreadable_images_name_the_file(tmp_path, content):
  (tmp_path / "broken.png").write_bytes(content)
  with pytest.raises(DatasetError, match=r"broken.png: cannot read image"):
    read_image(tmp_path / "broken.png")


def _blender(tmp_path, meta_changes=None, frame_changes=None):
  """A one-frame NeRF Synthetic folder with `changes` applied to its json."""
  (tmp_path / "train").mkdir(exist_ok=True)
  Image.fromarray(np.zeros((4, 6, 4), np.uint8)).save(tmp_path / "train" / "r_0.png")
  c2w = np.linalg.inv(np.diag([1.0, -1, -1, 1]) @ W2C @ np.diag([1.0, -1, -1, 1]))
  frame = {"file_path": "./train/r_0", "transform_matrix": c2w.tolist(), **(frame_changes or {})}
  meta = {"camera_angle_x": 0.8, "frames": [frame], **(meta_changes or {})}
  (tmp_path / "transforms_train.json").write_text(json.dumps(meta))
  return tmp_path


@pytest.mark.parametrize("meta, frame, message", [
    ({"camera_angle_x": "0.8"}, {}, r"transforms_train.json: 'camera_angle_x' must be a finite "
                                    r"number, got '0.8'"),
    ({"camera_angle_x": True}, {}, "'camera_angle_x' must be a finite number, got True"),
    ({"camera_angle_x": 50.0}, {}, r"'camera_angle_x' = 50.0 is not in \(0, pi\) radians"),
    ({}, {"camera_angle_x": [0.8]}, r"frame 0: 'camera_angle_x' must be a finite number"),
    ({"fl_x": "500"}, {}, "'fl_x' must be a finite number, got '500'"),
    ({"fl_x": -5.0}, {}, "focal lengths must be > 0"),
    ({}, {"cx": None, "cy": NAN}, "frame 0: 'cy' must be a finite number, got nan"),
    ({"w": "6"}, {}, "'w' must be an integer, got '6'"),
    ({"w": 6.5}, {}, "'w' must be an integer, got 6.5"),
    ({"h": 8}, {}, r"frame 0: 'h' = 8 but the image is 6x4"),
    ({}, {"transform_matrix": [["a"] * 4] * 4}, r"frame 0: 'transform_matrix' must be a 3x4 or "
                                                r"4x4 matrix of numbers"),
    ({}, {"transform_matrix": [[1, 0], [0, 1, 0]]}, r"'transform_matrix' must be a 3x4 or 4x4"),
    ({}, {"transform_matrix": (np.diag([1.0, 1, -1, 1])).tolist()}, "a reflection"),
    ({}, {"transform_matrix": "identity"}, "'transform_matrix' must be a 3x4 or 4x4 matrix"),
    ({}, {"file_path": 3}, "'file_path' must be a non-empty string"),
    ({}, {"depth_file_path": 3}, "'depth_file_path' must be a non-empty string"),
    ({"frames": {"file_path": "x"}}, {}, "missing or empty 'frames' list"),
    # Camera models a pinhole cannot reproduce are refused, not read as pinholes.
    ({"camera_model": "OPENCV", "k1": 0.1}, {}, r"transforms_train.json: distortion coefficient "
                                                r"'k1' = 0.1 \(camera model OPENCV\)"),
    ({"camera_model": "OPENCV"}, {"p2": -0.01}, r"frame 0: distortion coefficient 'p2' = -0.01"),
    ({}, {"k2": 0.02}, r"frame 0: distortion coefficient 'k2' = 0.02 \(camera model PINHOLE\)"),
    ({"camera_model": "OPENCV_FISHEYE"}, {}, r"'camera_model' is 'OPENCV_FISHEYE', which the "
                                             r"pinhole renderer cannot reproduce"),
    ({}, {"camera_model": 3}, "frame 0: 'camera_model' must be a string, got 3"),
    ({"k3": "0"}, {}, "'k3' must be a finite number, got '0'"),
    ({"camera_angle_x": None, "fl_y": 50.0}, {}, r"a vertical focal length \('fl_y' or "
                                                 r"'camera_angle_y'\) without a horizontal one"),
    ({"camera_angle_y": 4.0}, {}, r"'camera_angle_y' = 4.0 is not in \(0, pi\) radians"),
    ({}, {"name": 3}, "frame 0: 'name' must be a non-empty string, got 3"),
])
def test_blender_json_field_table(tmp_path, meta, frame, message):
  root = _blender(tmp_path, meta, frame)
  with pytest.raises(DatasetError, match=message):
    load_blender(root, "train")


@pytest.mark.parametrize("meta, frame, expected", [
    ({"camera_model": "OPENCV", "k1": 0.0, "k2": 0, "p1": 0.0, "p2": 0.0}, {},
     {"fx": 3.0 / np.tan(0.4), "fy": 3.0 / np.tan(0.4)}),  # zero distortion: a pinhole
    ({"camera_angle_y": 0.6}, {}, {"fx": 3.0 / np.tan(0.4), "fy": 2.0 / np.tan(0.3)}),
    ({"fl_y": 7.5}, {}, {"fx": 3.0 / np.tan(0.4), "fy": 7.5}),  # fl_y beside camera_angle_x
    ({"fl_x": 9.0}, {"fl_y": 8.0}, {"fx": 9.0, "fy": 8.0}),
    ({"fl_x": 9.0}, {}, {"fx": 9.0, "fy": 9.0}),  # square pixels
])
def test_blender_intrinsics_per_axis(tmp_path, meta, frame, expected):
  """Per axis: the focal length, else the field of view over the image size (6 x 4 here);
  no vertical one: fy = fx."""
  cameras = load_blender(_blender(tmp_path, meta, frame), "train").cameras
  for key, value in expected.items():
    np.testing.assert_allclose(float(getattr(cameras, key)[0]), value, rtol=1e-6)


def _two_frames(tmp_path, second):
  root = _blender(tmp_path)
  meta = json.loads((root / "transforms_train.json").read_text())
  meta["frames"].append({**meta["frames"][0], **second})
  (root / "transforms_train.json").write_text(json.dumps(meta))
  return root


@pytest.mark.parametrize("second, message", [
    ({}, r"frame 1: the image .*r_0.png is also that of frame 0; every frame must be a distinct"),
    ({"file_path": "./train/r_0.png"}, r"frame 1: the image .*r_0.png is also that of frame 0"),
    ({"file_path": "./train/r_1", "name": "train/r_0"},
     r"frame 1: the view name 'train/r_0' is also that of frame 0"),
])
def test_blender_duplicate_frames_are_refused(tmp_path, second, message):
  root = _two_frames(tmp_path, second)
  Image.fromarray(np.zeros((4, 6, 4), np.uint8)).save(root / "train" / "r_1.png")
  with pytest.raises(DatasetError, match=message):
    load_blender(root, "train")


def test_blender_reads_an_absolute_file_path(tmp_path):
  """The image of an absolute `file_path` is read, and the view named by that path."""
  elsewhere = tmp_path / "elsewhere"
  elsewhere.mkdir()
  Image.fromarray(np.full((4, 6, 4), 255, np.uint8)).save(elsewhere / "x.png")
  (tmp_path / "data").mkdir()
  root = _two_frames(tmp_path / "data", {"file_path": str(elsewhere / "x.png")})
  views = load_blender(root, "train")
  assert views.names == ("train/r_0", (elsewhere / "x").as_posix())
  assert views.images[1].min() == 1.0


@pytest.mark.parametrize("text, message", [
    ('{"camera_angle_x": 0.8, "camera_angle_x": 0.9, "frames": []}',
     "the key 'camera_angle_x' appears twice in one json object"),
    ("[" * 100_000 + "]" * 100_000, "json nested too deeply"),
])
def test_json_that_a_reader_would_misread_is_refused(tmp_path, text, message):
  (tmp_path / "t.json").write_text(text)
  with pytest.raises(DatasetError, match=rf"t.json: {message}"):
    read_json(tmp_path / "t.json")


def test_blender_reads_16_bit_images_at_full_precision(tmp_path):
  root = _blender(tmp_path)
  values = np.random.default_rng(0).integers(0, 65536, (4, 6, 4), np.uint16)
  values[..., 3] = 65535  # opaque: the composite is the stored colour
  _png(root / "train" / "r_0.png", values)
  views = load_blender(root, "train")
  np.testing.assert_allclose(views.images[0], values[..., :3] / 65535.0, atol=1e-7)


@pytest.mark.parametrize("array, message", [
    (np.array([{"pose": 1}], dtype=object), "cannot read"),  # pickled objects are refused
    (np.zeros((2, 17), np.complex64), "expected a real number array, got dtype complex64"),
    (np.full((2, 17), "1.0"), "expected a real number array, got dtype <U3"),
    (np.zeros((2, 16)), r"expected an array of shape \[V, 17\]"),
    ({"poses": np.zeros((2, 17))}, r"an .npz archive, not a .npy array"),
])
def test_llff_poses_file_table(tmp_path, array, message):
  (tmp_path / "images_8").mkdir()
  if isinstance(array, dict):  # np.savez to a file object keeps the .npy name
    with open(tmp_path / "poses_bounds.npy", "wb") as f:
      np.savez(f, **array)
  else:
    np.save(tmp_path / "poses_bounds.npy", array, allow_pickle=True)
  with pytest.raises(DatasetError, match=rf"poses_bounds.npy: .*{message}"):
    load_llff(tmp_path)


@pytest.mark.parametrize("files, message", [
    ({"a.png": (16, 16), "a.jpg": (16, 16)}, r"images_8: two views have the file stem 'a'"),
    ({"a.png": (16, 16), "b.png": (16, 8)}, r"b.png: image is 8x16 but a.png is 16x16"),
    ({"a.png": (16, 8), "b.png": (16, 8)}, r"a.png: image is 8x16, not a scaled copy of the "
                                           r"16x16 that .*poses_bounds.npy row 0 was calibrated"),
])
def test_llff_images_table(tmp_path, files, message):
  cams = Camera.create(np.stack([W2C] * 2), 8.0, 8.0, 8.0, 8.0, 16, 16)
  np.save(tmp_path / "poses_bounds.npy", poses_bounds_from_cameras(cams, [[1.0, 5.0]] * 2))
  (tmp_path / "images_8").mkdir()
  for name, (h, w) in files.items():
    Image.fromarray(np.zeros((h, w, 3), np.uint8)).save(tmp_path / "images_8" / name)
  with pytest.raises(DatasetError, match=message):
    load_llff(tmp_path)


# ---------------------------------------------------------------------- COLMAP models

IMAGES_AB = ((1, (1.0, 0.0, 0.0, 0.0), "a.png"), (2, (1.0, 0.0, 0.0, 0.0), "b.png"))


def _colmap_binary(root, cameras=((1, 1, 40, 30, (50.0, 60.0, 20.0, 15.0)),), images=IMAGES_AB,
                   points=((1, (0.1, 0.2, 0.3), 1), (2, (0.0, 0.1, 0.2), 0))):
  """A COLMAP sparse model written byte by byte in the documented binary layout (without the
  rigs and frames of COLMAP 3.12+, which pycolmap then makes one per camera and image), and a
  40 x 30 image per name.

  cameras: (id, model id, width, height, params); images: (id, (qw, qx, qy, qz), name), each
  at t = (0, 0, 2) with camera 1 and one 2D point; points: (id, xyz, track length), each
  track element (image 1, 2D point 0).
  """
  sparse = root / "sparse" / "0"
  sparse.mkdir(parents=True, exist_ok=True)
  count = lambda items: struct.pack("<Q", len(items))
  (sparse / "cameras.bin").write_bytes(count(cameras) + b"".join(
      struct.pack("<IiQQ", i, m, w, h) + struct.pack(f"<{len(ps)}d", *ps)
      for i, m, w, h, ps in cameras))
  (sparse / "images.bin").write_bytes(count(images) + b"".join(
      struct.pack("<I4d3dI", i, *q, 0.0, 0.0, 2.0, 1) + name.encode() + b"\0"
      + struct.pack("<Qddq", 1, 5.0, 5.0, -1) for i, q, name in images))
  (sparse / "points3D.bin").write_bytes(count(points) + b"".join(
      struct.pack("<Q3d3BdQ", i, *xyz, 200, 100, 50, 0.5, t) + struct.pack("<II", 1, 0) * t
      for i, xyz, t in points))
  (root / "images").mkdir(exist_ok=True)
  for _, _, name in images:
    Image.fromarray(np.zeros((30, 40, 3), np.uint8)).save(root / "images" / name)
  return root


def _cut(name, n):
  def damage(sparse):
    data = (sparse / name).read_bytes()
    (sparse / name).write_bytes(data[:-n])
  return damage


def _patch(name, offset, value):
  def damage(sparse):
    data = bytearray((sparse / name).read_bytes())
    data[offset:offset + len(value)] = value
    (sparse / name).write_bytes(bytes(data))
  return damage


IMAGE_RECORD = 4 + 56 + 4 + len("a.png\0") + 8 + 24  # images.bin: one image with one 2D point
COLMAP_FILES_BAD = {  # damage to the model of `_colmap_binary`: the expected message
    "points3D.bin 7 bytes short": (_cut("points3D.bin", 7),
                                   r"points3D.bin: truncated: 3D point record 1 \(51 bytes"),
    "points3D.bin 1 byte short": (_cut("points3D.bin", 1), r"points3D.bin: truncated: 3D point"),
    "a track of 10^12 elements": (_patch("points3D.bin", 8 + 43, struct.pack("<Q", 10 ** 12)),
                                  r"the track of 3D point record 0 runs past the end"),
    "10^15 points declared": (_patch("points3D.bin", 0, struct.pack("<Q", 10 ** 15)),
                              r"declares 1000000000000000 3D points of at least 51 bytes"),
    "bytes after the last point": (lambda sp: open(sp / "points3D.bin", "ab").write(b"\0" * 9),
                                   "9 bytes follow the last of the 3D points"),
    "an empty points3D.bin": (lambda sp: (sp / "points3D.bin").write_bytes(b""),
                              "points3D.bin: the file is empty"),
    "images.bin cut in a name": (
        lambda sp: (sp / "images.bin").write_bytes((sp / "images.bin").read_bytes()[
            :8 + IMAGE_RECORD + 66]),
        "the name of image 2 has no terminating NUL byte"),
    "10^12 2D points declared": (
        _patch("images.bin", 8 + 64 + 6, struct.pack("<Q", 10 ** 12)),
        r"images.bin: truncated: the 1000000000000 2D points of image 'a.png'"),
    "an image of a missing camera": (_patch("images.bin", 8 + 60, struct.pack("<I", 7)),
                                     r"image 1 \('a.png'\) refers to camera 7, which "
                                     "cameras.bin does not hold"),
    "cameras.bin cut in the parameters": (_cut("cameras.bin", 5),
                                          r"cameras.bin: truncated: the 4 parameters of camera 1"),
    "an unknown camera model": (_patch("cameras.bin", 12, struct.pack("<i", 99)),
                                "camera 1 has the model id 99, which COLMAP does not define"),
}


@pytest.mark.parametrize("case", COLMAP_FILES_BAD)
def test_colmap_binary_files_are_walked_before_pycolmap(tmp_path, case):
  """pycolmap trusts the counts: on these files it exhausts the memory, loops for ever or
  reads leftover values. The walk refuses them first, naming the file and the record."""
  pytest.importorskip("pycolmap")
  root = _colmap_binary(tmp_path)
  damage, message = COLMAP_FILES_BAD[case]
  damage(root / "sparse" / "0")
  with pytest.raises(DatasetError, match=message):
    load_colmap(root)


@pytest.mark.parametrize("name, cut", [("frames.bin", 3), ("rigs.bin", 3)])
def test_colmap_rigs_and_frames_files_are_walked_too(tmp_path, name, cut):
  """The rigs.bin and frames.bin that COLMAP 3.12+ (and pycolmap's writer) add."""
  pytest.importorskip("pycolmap")
  cams = Camera.create(np.stack([W2C] * 2), 6.0, 6.0, 4.0, 4.0, 8, 8)
  sparse = export_colmap(tmp_path, Views(np.zeros((2, 8, 8, 3), np.float32), cams))
  load_colmap(tmp_path)
  _cut(name, cut)(sparse)
  with pytest.raises(DatasetError, match=rf"{name}: truncated"):
    load_colmap(tmp_path)


Q0 = (0.0, 0.0, 0.0, 0.0)
COLMAP_FIELDS_BAD = {  # _colmap_binary arguments: the expected message
    "a zero quaternion": ({"images": ((1, Q0, "a.png"), IMAGES_AB[1])},
                          r"image 'a.png': the rotation quaternion \(qw, qx, qy, qz\) = "
                          r"\[0.0, 0.0, 0.0, 0.0\] has norm 0"),
    "a quaternion of norm 2": ({"images": ((1, (2.0, 0, 0, 0), "a.png"), IMAGES_AB[1])},
                               "has norm 2; COLMAP stores unit quaternions"),
    "an image listed twice": ({"images": (IMAGES_AB[0], (2, (1.0, 0, 0, 0), "a.png"))},
                              "the image 'a.png' is listed twice; view names must be unique"),
    "a.png and a.jpg": ({"images": (IMAGES_AB[0], (2, (1.0, 0, 0, 0), "a.jpg"))},
                        "the images 'a.jpg' and 'a.png' both give the view name 'a'"),
    "camera width 0": ({"cameras": ((1, 1, 0, 30, (50.0, 60.0, 20.0, 15.0)),)},
                       r"camera 1 \(used by image 'a.png'\): invalid image size width=0"),
    "a NaN 3D point": ({"points": ((1, (0.1, NAN, 0.3), 0),)}, "3D point 1 is not finite"),
}


@pytest.mark.parametrize("case", COLMAP_FIELDS_BAD)
def test_colmap_model_field_table(tmp_path, case):
  pytest.importorskip("pycolmap")
  kwargs, message = COLMAP_FIELDS_BAD[case]
  with pytest.raises(DatasetError, match=message):
    load_colmap(_colmap_binary(tmp_path, **kwargs))


COLMAP_TEXT_BAD = {  # (cameras.txt, images.txt pose lines, points3D.txt): the expected message
    "a name with a space": ("1 PINHOLE 40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 1 my a.png"], "",
                            r"images.txt line 1: the image name 'my a.png' contains a space"),
    "colour 300": ("1 PINHOLE 40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 1 a.png"],
                   "4 1 2 3 300 128 0 0.5", r"points3D.txt line 1: colour R = 300 is outside "
                                            r"0..255"),
    "an image of a missing camera": ("1 PINHOLE 40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 3 a.png"],
                                     "", "image 'a.png' refers to camera 3, which cameras.txt"),
    "width -40": ("1 PINHOLE -40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 1 a.png"], "",
                  "invalid image size width=18446744073709551576"),
    "a line pycolmap cannot parse": ("1 PINHOLE 40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 1 a.png"],
                                     "4 1 x 3 255 128 0 0.5", "cannot read the COLMAP model"),
}


@pytest.mark.parametrize("case", COLMAP_TEXT_BAD)
def test_colmap_text_model_table(tmp_path, case):
  pytest.importorskip("pycolmap")
  camera, images, points, message = COLMAP_TEXT_BAD[case]
  sparse = tmp_path / "sparse" / "0"
  sparse.mkdir(parents=True)
  (sparse / "cameras.txt").write_text(camera + "\n")
  (sparse / "images.txt").write_text("".join(line + "\n\n" for line in images))
  (sparse / "points3D.txt").write_text(points + "\n")
  (tmp_path / "images").mkdir()
  Image.fromarray(np.zeros((30, 40, 3), np.uint8)).save(tmp_path / "images" / "a.png")
  with pytest.raises(DatasetError, match=message):
    load_colmap(tmp_path)


# ---------------------------------------------------------------------- .ply headers

PLY_PROPERTIES = "".join(f"property float {p}\n" for p in (
    "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
    "rot_0", "rot_1", "rot_2", "rot_3"))


@pytest.mark.parametrize("header, data, message", [
    ("format binary_little_endian 1.0\nelement vertex 100000000000\n" + PLY_PROPERTIES,
     b"\0" * 60, "truncated: the header declares 100000000000 vertex rows of 56 bytes, but the "
                 "data ends in row 1, at property 'y'"),
    ("format ascii 1.0\nelement vertex 100000000000\n" + PLY_PROPERTIES, b"1 2 3\n",
     "ASCII PLY"),
    ("format binary_little_endian 1.0\nelement face 10000000000\nproperty list uchar int idx\n"
     "element vertex 1\n" + PLY_PROPERTIES, b"\0" * 60,
     "truncated: the header declares 10000000000 face rows of at least 1 bytes"),
], ids=["10^11 vertices", "ascii", "10^10 list rows"])
def test_ply_headers_are_checked_against_the_file_before_reading(tmp_path, header, data, message):
  """plyfile allocates the rows a header declares before reading them (terabytes here)."""
  path = tmp_path / "bad.ply"
  path.write_bytes(b"ply\n" + header.encode() + b"end_header\n" + data)
  with pytest.raises(DatasetError, match=rf"bad.ply: {message}"):
    load_ply(path)


# ---------------------------------------------------------------------- Views, exports

VIEWS = Views(np.zeros((2, 8, 8, 3), np.float32),
              Camera.create(np.stack([W2C] * 2), 6.0, 6.0, 4.0, 4.0, 8, 8), names=("a", "b"))


@pytest.mark.parametrize("changes, message", [
    ({"names": ("a", "a")}, "Views.names repeats 'a'"),
    ({"names": ("a",)}, r"Views.names must hold 2 names \(one per view\) or none, got 1"),
    ({"alphas": np.ones((2, 8, 7))}, r"Views.alphas must have shape \[2, 8, 8\]"),
    ({"images": np.zeros((2, 8, 8, 3), np.uint8)}, "Views.images must be floats"),
    ({"cameras": Camera.create(W2C, 6.0, 6.0, 4.0, 4.0, 8, 8)},
     r"Views.cameras must be a Camera batched over \[2\] .*got batch \(\)"),
])
@pytest.mark.parametrize("export", ["blender", "colmap"])
def test_views_are_checked_before_export(tmp_path, changes, message, export):
  views = VIEWS.replace(**changes)
  with pytest.raises(ValueError, match=message):
    views.validate()
  if export == "colmap":
    pytest.importorskip("pycolmap")
  with pytest.raises(ValueError, match=message):
    (export_blender if export == "blender" else export_colmap)(tmp_path, views)
  assert not any(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize("cameras, bounds, message", [
    (VIEWS.cameras, np.ones((3, 2)), r"bounds must have shape \[V=2, 2\] \(near, far\)"),
    (Camera.create(np.stack([W2C] * 2), 6.0, 7.0, 4.0, 4.0, 8, 8), np.ones((2, 2)),
     r"cameras.fy\[0\] = 7.0, but LLFF stores one focal length .*: it must be 6.0"),
    (Camera.create(np.stack([W2C] * 2), 6.0, 6.0, 4.0, [4.0, 3.5], 8, 8), np.ones((2, 2)),
     r"cameras.cy\[1\] = 3.5, .* it must be 4.0"),
])
def test_llff_poses_are_written_only_when_the_format_holds_them(cameras, bounds, message):
  with pytest.raises(ValueError, match=message):
    poses_bounds_from_cameras(cameras, bounds)


def test_export_colmap_checks_its_points(tmp_path):
  pytest.importorskip("pycolmap")
  with pytest.raises(ValueError, match=r"points must hold xyz \[P, 3\] and rgb \[P, 3\]"):
    export_colmap(tmp_path, VIEWS, PointCloud(np.zeros((3, 3)), np.zeros((2, 3))))
  with pytest.raises(ValueError, match=r"points.xyz\[1\] is not finite"):
    export_colmap(tmp_path, VIEWS, PointCloud(np.array([[0, 0, 0], [NAN, 0, 0]]),
                                              np.zeros((2, 3))))
  with pytest.raises(ValueError, match=r"percentile must be a number in \[0, 50\)"):
    PointCloud(np.zeros((3, 3)), np.zeros((3, 3))).box(60)


# ====================================================================== the capture cache


@pytest.mark.parametrize("write, message", [
    (lambda p: p.write_bytes(b""), "unreadable cache entry"),
    (lambda p: p.write_bytes(b"PK\x03\x04 truncated"), "unreadable cache entry"),
    (lambda p: np.savez(p, radiance=np.zeros((4, 4, 3))), "has no array 'alpha'"),
    (lambda p: np.savez(p, radiance=np.zeros((4, 5, 3)), alpha=np.zeros((4, 4)),
                        depth=np.zeros((4, 4))), r"radiance has shape \(4, 5, 3\)"),
    (lambda p: np.savez(p, radiance=np.full((4, 4, 3), NAN), alpha=np.zeros((4, 4)),
                        depth=np.zeros((4, 4))), "radiance has non-finite values"),
    (lambda p: np.savez(p, radiance=np.array([None]), alpha=np.zeros((4, 4)),
                        depth=np.zeros((4, 4))), "unreadable cache entry"),  # pickled
])
def test_unusable_capture_cache_entries_are_recomputed(tmp_path, write, message):
  path = tmp_path / "rgbad-entry.npz"
  write(path)
  expected = {"radiance": (4, 4, 3), "alpha": (4, 4), "depth": (4, 4)}
  with pytest.warns(UserWarning, match=rf"rgbad-entry.npz: .*{message}|{message} .*rgbad-entry"):
    assert cache.load(path, expected) is None
  cache.save(path, {k: np.zeros(s, np.float32) for k, s in expected.items()})
  assert set(cache.load(path, expected)) == set(expected)  # the recomputed entry replaces it


# ====================================================================== atomic writes, checks


def test_a_writer_that_dies_leaves_the_previous_file_and_no_temporary(tmp_path):
  path = tmp_path / "table.md"
  _json.write_text(path, "complete")
  with pytest.raises(RuntimeError), _json.atomic_open(path) as f:
    f.write("half a ta")
    raise RuntimeError("killed mid-write")
  assert path.read_text() == "complete" and sorted(os.listdir(tmp_path)) == ["table.md"]
  with _json.atomic_path(tmp_path / "figure.png") as tmp:  # keeps the extension
    assert tmp.endswith(".png")
    Image.new("RGB", (2, 2)).save(tmp)
  assert sorted(os.listdir(tmp_path)) == ["figure.png", "table.md"]


@pytest.mark.parametrize("check, value, message", [
    (lambda c: config_checks.check_bool(c, "x"), 1, "config.x = 1: must be True or False"),
    (lambda c: config_checks.check_str(c, "x", non_empty=True), "", "must be a non-empty string"),
    (lambda c: config_checks.check_str(c, "x"), None, "config.x = None: must be a string"),
    (lambda c: config_checks.check_floats(c, "x", 2), (1.0, "2"), "must be 2 finite numbers"),
    (lambda c: config_checks.check_floats(c, "x", 2, increasing=True), (1, 1),
     "strictly increasing"),
    (lambda c: config_checks.check_floats(c, "x", 3, minimum=0), (1, -1, 1),
     "must be 3 finite numbers >= 0"),
    (lambda c: config_checks.check_int(c, "x", minimum=1), True, "must be an integer >= 1"),
    (lambda c: config_checks.check_float(c, "x"), float("inf"), "must be a finite number"),
    (lambda c: config_checks.check_int(c, "y"), 0, "config.y: the config has no such field"),
])
def test_config_check_table(check, value, message):
  with pytest.raises(ConfigError, match=message):
    check({"x": value})
