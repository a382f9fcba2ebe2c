"""Training data from a config: `load_dataset(config.data)` dispatches on `kind`.

* "synthetic": random ground-truth Gaussians rendered by `mfsample.render` from cameras on
  a sphere: posed images for free, no files, no Mitsuba (tests use it).
* "blender": a NeRF Synthetic scene (`config.path`, relative paths resolved against the
  repository root) via `mfsample.data.load_blender`.
* "scene": a Mitsuba scene of `mfsample.scenes` (optional extra), captured at the scene's
  candidate and test cameras.
* "colmap": a COLMAP capture (`mfsample.data.load_colmap`, optional extra `colmap`): every
  `holdout_every`-th image by name is a test view (the Mip-NeRF 360 / 3DGS split), and its
  sparse points come along for `model.init_from = "points"`.
* "llff": a forward-facing LLFF capture (`mfsample.data.load_llff`), split the same way.
* "nerfstudio": a nerfstudio capture (`mfsample.data.load_nerfstudio`, ns-process-data's
  `transforms.json`), split the same way, its `ply_file_path` points as the SfM points.
"""

import os
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.data import load_blender
from mfsample.data.views import Views
from mfsample.renderer import render
from mfsample.renderer.budget import render_with_budget
from mfsample.renderer.settings import RenderSettings
from mfsample.testing import random_gaussians


class Dataset(NamedTuple):
  """Training and test views of one scene.

  Attributes:
    train: `Views` to train on.
    test: `Views` to evaluate on.
    background: RGB tuple the images are composited on.
    bounds: (low [3], high [3]) box for the random initial point cloud
      (`config.init_bounds`; for a Mitsuba scene the cube around its bounding sphere; for a
      COLMAP capture the box of its points, for LLFF that of the views' frusta).
    points: the sparse SfM `mfsample.data.colmap.PointCloud` of a COLMAP or nerfstudio
      capture, else None.
  """

  train: Views
  test: Views
  background: tuple
  bounds: tuple
  points: object = None


def resolve_path(path):
  """`path` with `~` expanded, made absolute (relative paths: to the working directory)."""
  return Path(os.path.expanduser(str(path))).resolve()


def load_dataset(cfg) -> Dataset:
  """Loads the views that `cfg` (the `data` block of a training config) describes."""
  background = tuple(float(c) for c in cfg.background)
  bounds = (np.full(3, cfg.init_bounds[0], np.float32), np.full(3, cfg.init_bounds[1],
                                                                 np.float32))
  if cfg.kind == "synthetic":
    train, test = synthetic_views(cfg.synthetic, background)
  elif cfg.kind == "blender":
    train, test = _blender_views(cfg, background)
  elif cfg.kind == "scene":
    train, test, bounds = _scene_views(cfg, background)
  elif cfg.kind in ("colmap", "llff", "nerfstudio"):
    return _capture_dataset(cfg, background)
  else:
    raise ValueError(f"config.data.kind must be 'synthetic', 'blender', 'scene', 'colmap', "
                     f"'llff' or 'nerfstudio', got {cfg.kind!r}")
  return Dataset(train=train, test=test, background=background, bounds=bounds)


# ------------------------------------------------------------------------- synthetic


def synthetic_gaussians(num, seed, sh_degree=0, radius=0.6):
  """`num` random, fairly opaque Gaussians in the cube [-radius, radius]^3."""
  return random_gaussians(num, sh_degree=sh_degree, seed=seed, extent=radius,
                          scale_range=(0.04, 0.12), opacity_range=(0.6, 0.95))


def orbit_cameras(num, width, height, distance=3.0, fov_x=0.8, seed=0, offset=0.0):
  """`num` cameras on a sphere looking at the origin (a Fibonacci spiral, +z up)."""
  del seed  # the spiral is deterministic; kept for a uniform signature
  i = np.arange(num) + 0.5 + offset
  polar = np.arccos(np.clip(1.0 - 2.0 * i / (num + 2 * offset), -0.95, 0.95))
  azimuth = np.pi * (1.0 + 5.0**0.5) * i
  eye = distance * np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                             np.cos(polar)], axis=-1)
  return Camera.look_at(jnp.asarray(eye, jnp.float32), jnp.zeros(3), jnp.array([0.0, 0, 1]),
                        fov_x, width, height)


def render_views(gaussians, cameras, background, settings=None, names=None):
  """Renders `gaussians` into every camera: ground-truth `Views` for tests."""
  settings = settings or RenderSettings()
  images, alphas, depths = [], [], []
  bg = jnp.asarray(background, jnp.float32)
  for i in range(len(cameras)):
    out, settings = render_with_budget(render, settings, gaussians, cameras[i],
                                       background=bg)
    images.append(out.rgb)
    alphas.append(out.alpha)
    depths.append(out.expected_depth())
  names = tuple(names) if names else tuple(f"view_{i:03d}" for i in range(len(cameras)))
  return Views(jnp.clip(jnp.stack(images), 0.0, 1.0), cameras, jnp.stack(alphas),
               jnp.stack(depths), names)


def synthetic_views(cfg, background):
  """(train, test) `Views` of random Gaussians (`cfg`: the `data.synthetic` block)."""
  gt = synthetic_gaussians(cfg.num_gaussians, cfg.seed, cfg.sh_degree)
  train_cams = orbit_cameras(cfg.num_train, cfg.width, cfg.height, cfg.distance)
  test_cams = orbit_cameras(cfg.num_test, cfg.width, cfg.height, cfg.distance, offset=0.37)
  return (render_views(gt, train_cams, background),
          render_views(gt, test_cams, background,
                       names=[f"test_{i:03d}" for i in range(cfg.num_test)]))


# ------------------------------------------------------------------------- blender


def _blender_views(cfg, background):
  path = resolve_path(cfg.path)
  if not (path / "transforms_train.json").is_file():
    raise FileNotFoundError(
        f"No NeRF Synthetic scene at {path} (config.data.path={cfg.path!r}; relative paths "
        f"are resolved against the working directory). Expected transforms_train.json there.")
  train = load_blender(str(path), "train", downscale=cfg.downscale, background=background)
  test = load_blender(str(path), "test", downscale=cfg.downscale, background=background)
  if cfg.test_every > 1:
    test = test.subset(range(0, len(test), cfg.test_every))
  return train, test


# ------------------------------------------------------------------------- colmap, llff


def holdout_split(num, every):
  """(train indices, test indices) of `num` views: every `every`-th view from the first is a
  test view (Mip-NeRF 360 and 3DGS hold out every 8th image of a capture sorted by name)."""
  every = int(every)
  if every < 2:
    raise ValueError(f"config.data.holdout_every = {every}: must be an integer >= 2")
  index = np.arange(num)
  test = index[index % every == 0]
  train = index[index % every != 0]
  if len(train) == 0:
    raise ValueError(f"{num} view(s) and holdout_every = {every} leave no training view")
  return train, test


def _capture_dataset(cfg, background):
  from mfsample.data import load_colmap, load_llff, load_nerfstudio

  path = resolve_path(cfg.path)
  points = None
  if cfg.kind in ("colmap", "nerfstudio"):
    load = load_colmap if cfg.kind == "colmap" else load_nerfstudio
    views, points = load(path, factor=int(cfg.downscale), background=background)
    if len(points):
      bounds = points.box()
    else:  # no points: the box around the cameras
      centers = np.asarray(views.cameras.center, np.float64)
      radius = scene_extent(views.cameras)
      bounds = (centers.mean(0) - radius, centers.mean(0) + radius)
  else:
    views, depth_bounds = load_llff(path, factor=int(cfg.downscale))
    bounds = frustum_box(views.cameras, depth_bounds)
  train, test = holdout_split(len(views), cfg.holdout_every)
  bounds = tuple(np.asarray(b, np.float32) for b in bounds)
  return Dataset(train=views.subset(train), test=views.subset(test), background=background,
                 bounds=bounds, points=points)


def frustum_box(cameras: Camera, depth_bounds):
  """(low [3], high [3]) around what the cameras see between their near and far depths.

  Args:
    cameras: `Camera` batched over V.
    depth_bounds: [V, 2] (near, far) camera z-depths.
  """
  w2c = np.asarray(cameras.world_to_camera, np.float64)
  rot, t = w2c[:, :3, :3], w2c[:, :3, 3]
  fx, fy, cx, cy = (np.asarray(getattr(cameras, k), np.float64)[:, None]
                    for k in ("fx", "fy", "cx", "cy"))
  u = np.array([0.0, cameras.width, 0.0, cameras.width])[None]
  v = np.array([0.0, 0.0, cameras.height, cameras.height])[None]
  rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u + cx)], -1)  # [V, 4, 3]
  corners = []
  for d in (0, 1):
    cam = rays * np.asarray(depth_bounds, np.float64)[:, d, None, None]
    corners.append(np.einsum("vji,vcj->vci", rot, cam - t[:, None]))  # R^T (x - t)
  corners = np.concatenate(corners, axis=1).reshape(-1, 3)
  return corners.min(0), corners.max(0)


# ------------------------------------------------------------------------- scene


def _scene_views(cfg, background):
  try:
    from mfsample import scenes
  except ImportError as err:
    raise ImportError("config.data.kind='scene' needs mfsample.scenes and, for new captures, "
                      "the optional Mitsuba extra (pip install 'mfsample[scenes]')") from err
  scene = scenes.get_scene(cfg.scene)
  train_cams = scene.candidate_cameras(cfg.width, cfg.height, num=cfg.num_train)
  test_cams = scene.test_cameras(cfg.width, cfg.height, num=cfg.num_test)
  spp = scenes.DEFAULT_SPP if cfg.spp is None else cfg.spp
  cache = str(resolve_path(cfg.cache_dir)) if cfg.cache_dir else None
  kwargs = dict(spp=spp, cache_dir=cache, background=background)
  train = scenes.capture_views(scene, train_cams, **kwargs)
  test = scenes.capture_views(scene, test_cams, **kwargs)
  # The random initial cloud fills the cube around the scene's bounding sphere.
  center = np.asarray(scene.center, np.float32)
  bounds = (center - scene.radius, center + scene.radius)
  return train, test, bounds


def scene_extent(cameras: Camera):
  """3DGS scene extent: 1.1 x the largest distance of a camera centre from their mean.

  Scales the position learning rate, B_hat of the centres, and densification thresholds.
  With one camera (or coincident ones) it falls back to 1.1 x the distance to the origin.
  """
  centers = np.asarray(cameras.center).reshape(-1, 3)
  radius = np.max(np.linalg.norm(centers - centers.mean(0), axis=-1))
  if radius < 1e-6:
    radius = float(np.max(np.linalg.norm(centers, axis=-1)))
  return 1.1 * max(float(radius), 1e-3)


def to_device(views: Views):
  """`Views` with jnp arrays (the step indexes them inside jit)."""
  return views.replace(images=jnp.asarray(views.images, jnp.float32),
                       cameras=jax.tree.map(jnp.asarray, views.cameras))
