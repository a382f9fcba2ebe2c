"""Synthetic scenes for tests, benchmarks and notebooks."""

import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.data import synthetic
from mfsample.data.synthetic import random_gaussians

__all__ = ["orbit_camera", "random_gaussians", "write_tiny_capture"]


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

  Random Gaussians (`mfsample.data.synthetic.synthetic_gaussians`, in [-0.6, 0.6]^3) are
  rendered by `mfsample.render` from `num_views` cameras around them (`size` x `size`,
  white background, the training default) and written with `mfsample.data.export_colmap`
  (needs pycolmap), their centres as the sparse points; the Gaussians themselves go to
  `point_cloud.ply` (3DGS layout): a "pretrained" model that renders the capture exactly.

  Returns:
    (capture folder, path of the .ply), both under `path`.
  """
  from pathlib import Path

  from mfsample.data import PointCloud, export_colmap
  from mfsample.data.ply import export_gaussians

  root = Path(path)
  gaussians = synthetic.synthetic_gaussians(num_gaussians, seed)
  views = synthetic.render_views(gaussians, synthetic.orbit_cameras(num_views, size, size),
                                 (1.0, 1.0, 1.0))
  xyz = np.asarray(gaussians.means, np.float32)
  colors = np.clip(np.asarray(gaussians.sh)[:, 0] * 0.28209479177387814 + 0.5, 0.0, 1.0)
  export_colmap(root / "capture", views.replace(names=()), PointCloud(xyz, colors),
                overwrite=True)
  return root / "capture", export_gaussians(root / "point_cloud.ply", gaussians)
