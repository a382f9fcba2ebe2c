"""Synthetic scenes for tests, benchmarks and notebooks."""

import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.gaussians import Gaussians


def random_gaussians(num, *, sh_degree=3, seed=0, extent=1.0, scale_range=(0.01, 0.1),
                     opacity_range=(0.1, 1.0), dtype=jnp.float32):
  """`num` random Gaussians with centres uniform in [-extent, extent]^3.

  Scales are log-uniform in `scale_range` (times `extent`), rotations uniform, SH
  coefficients small so colours stay in a visible range.
  """
  rng = np.random.default_rng(seed)
  lo, hi = np.log(scale_range[0] * extent), np.log(scale_range[1] * extent)
  k = (sh_degree + 1) ** 2
  sh = rng.normal(0.0, 0.3, (num, k, 3))
  sh[:, 1:] *= 0.5
  return Gaussians(
      means=jnp.asarray(rng.uniform(-extent, extent, (num, 3)), dtype),
      scales=jnp.asarray(np.exp(rng.uniform(lo, hi, (num, 3))), dtype),
      quats=jnp.asarray(rng.normal(size=(num, 4)), dtype),
      opacities=jnp.asarray(rng.uniform(*opacity_range, (num,)), dtype),
      sh=jnp.asarray(sh, dtype),
  )


def orbit_camera(width, height, *, azimuth=0.3, elevation=0.4, distance=3.5, fov_x=0.9,
                 target=(0.0, 0.0, 0.0)):
  """A camera on a sphere around `target` (up = +z), looking at it."""
  target = np.asarray(target, np.float64)
  eye = target + distance * np.array([np.cos(elevation) * np.cos(azimuth),
                                      np.cos(elevation) * np.sin(azimuth),
                                      np.sin(elevation)])
  return Camera.look_at(jnp.asarray(eye, jnp.float32), jnp.asarray(target, jnp.float32),
                        jnp.array([0.0, 0.0, 1.0]), fov_x, width, height)


def write_tiny_capture(path, *, num_views=8, size=32, num_gaussians=200, seed=0):
  """A tiny COLMAP capture and the 3DGS model that made it, as files: stand-ins for yours.

  Random Gaussians (`mfsample.train.data.synthetic_gaussians`, in [-0.6, 0.6]^3) are
  rendered by `mfsample.render` from `num_views` cameras around them (`size` x `size`,
  white background, the training default) and written with `mfsample.data.export_colmap`
  (needs pycolmap), their
  centres as the sparse points; the Gaussians themselves go to `point_cloud.ply` (3DGS
  layout): a "pretrained" model that renders the capture exactly.

  Returns:
    (capture folder, path of the .ply), both under `path`.
  """
  from pathlib import Path

  from mfsample.data import PointCloud, export_colmap
  from mfsample.data.ply import export_gaussians
  from mfsample.train.data import orbit_cameras, render_views, synthetic_gaussians

  root = Path(path)
  gaussians = synthetic_gaussians(num_gaussians, seed)
  views = render_views(gaussians, orbit_cameras(num_views, size, size), (1.0, 1.0, 1.0))
  xyz = np.asarray(gaussians.means, np.float32)
  colors = np.clip(np.asarray(gaussians.sh)[:, 0] * 0.28209479177387814 + 0.5, 0.0, 1.0)
  export_colmap(root / "capture", views.replace(names=()), PointCloud(xyz, colors),
                overwrite=True)
  return root / "capture", export_gaussians(root / "point_cloud.ply", gaussians)
