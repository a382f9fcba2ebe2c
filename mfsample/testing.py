"""Synthetic scenes for tests, benchmarks, notebooks and the docs' examples: no files needed.

* `random_gaussians`: random `Gaussians` (the renderer's tests and benchmarks).
* `synthetic_views`: random ground-truth Gaussians seen from cameras around them, as `Views`
  (what `mfsample.fit` trains on), and the Gaussians themselves.
* `light_captures`: a diffuse shell of Gaussians captured under SH lights (what
  `mfsample.lighting.fit_relightable` trains on).
* `write_tiny_capture`: a tiny COLMAP capture and the 3DGS model that made it, as files.
"""

import numpy as np

from mfsample import arg_checks
from mfsample.camera import Camera
from mfsample.data import synthetic
from mfsample.data.synthetic import random_gaussians

__all__ = ["light_captures", "random_gaussians", "synthetic_views", "write_tiny_capture"]


def synthetic_views(num_views=12, *, size=32, num_gaussians=200, seed=0,
                    background=(1.0, 1.0, 1.0), distance=3.0):
  """Random ground-truth Gaussians in [-0.6, 0.6]^3 rendered by `mfsample.render` from
  `num_views` cameras on a spiral around them (+z up, looking at the origin).

  Returns:
    (`Views` [num_views] of size x size images, with exact coverage and depth; the ground
    truth `Gaussians`).
  """
  arg_checks.check_int("num_views", num_views, minimum=1)
  arg_checks.check_int("size", size, minimum=1)
  truth = synthetic.synthetic_gaussians(num_gaussians, seed)
  cameras = synthetic.orbit_cameras(num_views, size, size, distance)
  return synthetic.render_views(truth, cameras, background), truth


def light_captures(cameras: Camera, lights, *, num_gaussians=150, seed=0, radius=0.5):
  """Captures of a diffuse shell of random Gaussians (radius `radius`, about the origin) at
  `cameras` under each of `lights`: linear radiance on black.

  Args:
    cameras: `Camera` [V].
    lights: [L, n] SH lights (n = 4, 9 or 16).

  Returns:
    images [L, V, H, W, 3] float32.
  """
  from mfsample.lighting.captures import capture_many, synthetic_light_data

  lights = np.asarray(lights, np.float64)
  truth = synthetic.synthetic_scene(num_gaussians, seed, radius=radius)
  bounds = (np.full(3, -radius - 0.2), np.full(3, radius + 0.2))
  data = synthetic_light_data(truth, seed, cameras, cameras[:1], lights.shape[-1],
                              bounds=bounds)
  return capture_many(data.train_basis, lights)


def write_tiny_capture(path, *, num_views=8, size=32, num_gaussians=200, seed=0,
                       sparse="sparse/0", background=(1.0, 1.0, 1.0)):
  """A tiny COLMAP capture and the 3DGS model that made it, as files: stand-ins for yours.

  Random Gaussians (`mfsample.data.synthetic.synthetic_gaussians`, in [-0.6, 0.6]^3) are
  rendered by `mfsample.render` from `num_views` cameras around them (`size` x `size`) and
  written with `mfsample.data.export_colmap` (needs pycolmap), their centres as the sparse
  points; the Gaussians themselves go to `point_cloud.ply` (3DGS layout): a "pretrained"
  model that renders the capture exactly.

  Args:
    sparse: where the sparse model goes in the capture: "sparse/0" (COLMAP's mapper and
      Mip-NeRF 360) or "sparse" (`colmap image_undistorter --output_type COLMAP`). Either
      way the capture has `images/` only, no downscaled copies.
    background: [3] colour the views are rendered on: white (the training configs'
      default) or black (3DGS's default, the `colmap` variants').

  Returns:
    (capture folder, path of the .ply), both under `path`.
  """
  from pathlib import Path

  from mfsample.data import PointCloud, export_colmap
  from mfsample.data.ply import export_gaussians

  if sparse not in ("sparse/0", "sparse"):
    raise ValueError(f"sparse must be 'sparse/0' or 'sparse', got {sparse!r}")
  root = Path(path)
  gaussians = synthetic.synthetic_gaussians(num_gaussians, seed)
  views = synthetic.render_views(gaussians, synthetic.orbit_cameras(num_views, size, size),
                                 tuple(float(c) for c in background))
  xyz = np.asarray(gaussians.means, np.float32)
  colors = np.clip(np.asarray(gaussians.sh)[:, 0] * 0.28209479177387814 + 0.5, 0.0, 1.0)
  model = export_colmap(root / "capture", views.replace(names=()), PointCloud(xyz, colors),
                        overwrite=True)
  if sparse == "sparse":  # the undistorter's layout: the model files directly in sparse/
    for file in sorted(Path(model).iterdir()):
      file.replace(Path(model).parent / file.name)
    Path(model).rmdir()
  return root / "capture", export_gaussians(root / "point_cloud.ply", gaussians)
