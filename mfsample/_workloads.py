"""Renderer workloads that the benchmark scripts share: gsplat's garden and random scenes.

The garden workload is the one peers publish renderer timings on: gsplat's test data (a
point cloud of the Mip-NeRF 360 garden capture with three cameras at 648 x 420, in
`test_garden.npz`) cropped to [-2, 2]^3, with the random attributes gsplat's own benchmarks
draw (`gsplat/_helper.py::load_test_data`): scales U[1e-4, 0.02] per axis, uniformly random
unit quaternions, opacities U[0, 1]; the point colours become the SH DC term. mfsample renders
at SH degree 3; the higher SH coefficients are small random values, so every coefficient
has a gradient.

Without the file, `garden` generates a stand-in with the same statistics (as many points,
uniform in the crop box, the same attribute distributions, the same image size and focal
length, seen from 4 units away): the same amount of input, but not the same geometry, so its
tile intersections (and times) differ from the real garden's.
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.gaussians import Gaussians
from mfsample.orbits import orbit_camera
from mfsample.testing import random_gaussians

GARDEN_CROP = 2.0  # gsplat's crop box [-2, 2]^3
GARDEN_POINTS = 111_785  # garden's points inside the crop box
GARDEN_SIZE = (648, 420)
GARDEN_FOCAL = 480.6  # pixels, gsplat's Ks (fx ~ fy)
_SH_C0 = 0.28209479177387814  # Y_0^0: colour = C0 * sh_0 + 0.5


class Workload(NamedTuple):
  """A scene, the camera it is rendered from, and where it came from."""

  gaussians: Gaussians
  camera: Camera
  source: str  # a path, or a description of the generated scene


def garden(path=None, *, shrink=1, seed=0, sh_degree=3):
  """gsplat's garden workload (see the module docstring), or its generated stand-in.

  Args:
    path: `test_garden.npz`; None or "" generates the stand-in.
    shrink: keep every shrink^2-th point and divide the image size and intrinsics by
      `shrink` (1: the real size; larger for quick checks).
    seed: of the random attributes (and of the stand-in's points).
    sh_degree: of the Gaussians' SH colour.

  Returns:
    `Workload` with camera 0 of the file.
  """
  rng = np.random.default_rng(seed)
  if path:
    try:
      data = np.load(path)
      means, colors = data["means3d"], data["colors"] / 255.0
      w2c, k = data["viewmats"][0], data["Ks"][0]
      width, height = int(data["width"]), int(data["height"])
    except (OSError, KeyError, ValueError) as e:
      raise ValueError(f"{path}: not gsplat's test_garden.npz (means3d, colors, viewmats, Ks, "
                       f"width, height): {e}") from e
    keep = np.all((means >= -GARDEN_CROP) & (means <= GARDEN_CROP), axis=-1)
    means, colors = means[keep], colors[keep]
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    source = str(path)
  else:
    means = rng.uniform(-GARDEN_CROP, GARDEN_CROP, (GARDEN_POINTS, 3))
    colors = rng.uniform(0.0, 1.0, (GARDEN_POINTS, 3))
    (width, height), fx = GARDEN_SIZE, GARDEN_FOCAL
    fy, cx, cy = fx, width / 2, height / 2
    eye = np.array([0.0, -4.0, 1.0])
    w2c = None
    source = "generated stand-in for gsplat's garden"
  means, colors = means[::shrink * shrink], colors[::shrink * shrink]
  n = len(means)
  quats = rng.normal(size=(n, 4))
  sh = rng.normal(0.0, 0.05, (n, (sh_degree + 1) ** 2, 3))
  sh[:, 0] = (colors - 0.5) / _SH_C0
  f32 = lambda x: jnp.asarray(x, jnp.float32)
  gaussians = Gaussians(
      means=f32(means), scales=f32(rng.uniform(1e-4, 0.02, (n, 3))),
      quats=f32(quats / np.linalg.norm(quats, axis=-1, keepdims=True)),
      opacities=f32(rng.uniform(0.0, 1.0, n)), sh=f32(sh))
  width, height = -(-width // shrink), -(-height // shrink)
  fx, fy, cx, cy = fx / shrink, fy / shrink, cx / shrink, cy / shrink
  if w2c is None:
    fov_x = 2.0 * np.arctan(0.5 * width / fx)
    camera = Camera.look_at(f32(eye), jnp.zeros(3), jnp.array([0.0, 0.0, 1.0]), fov_x, width,
                            height)
  else:
    camera = Camera.create(f32(w2c), fx, fy, cx, cy, width, height)
  return Workload(gaussians, camera, source)


def random_cell(num, resolution, *, seed=0):
  """`num` random Gaussians (SH degree 3, scales 0.005-0.05 in [-1, 1]^3) seen at
  `resolution` x `resolution` from an orbit camera 3.5 units away: the cells of
  `benchmarks/render.py`."""
  gaussians = random_gaussians(num, sh_degree=3, seed=seed, scale_range=(0.005, 0.05))
  camera = orbit_camera(0.3, 0.4, width=resolution, height=resolution, distance=3.5, fov_x=0.9)
  return Workload(gaussians, camera, f"{num} random Gaussians at {resolution} x {resolution}")
