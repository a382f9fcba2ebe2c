"""Datasets from a config: `load_dataset(config.data)` dispatches on `config.data.kind`.

`DATA_KINDS` is the one definition of what a training config's `data.kind` may be; the
validators, the planning pools (`mfsample.planning.pool`) and the docs read it. A new kind is
a loader `(cfg, background) -> Dataset` and one entry here.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.data import synthetic
from mfsample.data._io import resolve_path
from mfsample.data.blender import load_blender
from mfsample.data.views import Views


class Dataset(NamedTuple):
  """Training and test views of one scene.

  Attributes:
    train: `Views` to train on.
    test: `Views` to evaluate on.
    background: RGB tuple the images are composited on.
    bounds: (low [3], high [3]) box for the random initial point cloud
      (`config.init_bounds`; for a Mitsuba scene the cube around its bounding sphere; for a
      COLMAP capture the box of its points, for LLFF that of the views' frusta).
    points: the sparse SfM `mfsample.data.colmap.PointCloud` of a COLMAP capture, else None.
  """

  train: Views
  test: Views
  background: tuple
  bounds: tuple
  points: object = None


class DataKind(NamedTuple):
  """One kind of dataset.

  Attributes:
    load: (the `data` block of a config, background RGB tuple) -> `Dataset`.
    reads_path: whether the dataset is files at `config.data.path` (a fixed pool of views,
      no oracle for new poses).
    summary: one line for the docs and for error messages.
  """

  load: object
  reads_path: bool
  summary: str


def load_dataset(cfg) -> Dataset:
  """Loads the views that `cfg` (the `data` block of a training config) describes."""
  if cfg.kind not in DATA_KINDS:
    raise ValueError(f"config.data.kind must be one of {', '.join(map(repr, DATA_KINDS))}, "
                     f"got {cfg.kind!r}")
  return DATA_KINDS[cfg.kind].load(cfg, tuple(float(c) for c in cfg.background))


def _init_bounds(cfg):
  return (np.full(3, cfg.init_bounds[0], np.float32), np.full(3, cfg.init_bounds[1],
                                                               np.float32))


# ------------------------------------------------------------------------- synthetic


def _synthetic(cfg, background):
  """Random ground-truth Gaussians seen from orbit cameras (`cfg.synthetic`)."""
  s = cfg.synthetic
  gt = synthetic.synthetic_gaussians(s.num_gaussians, s.seed, s.sh_degree)
  train_cams = synthetic.orbit_cameras(s.num_train, s.width, s.height, s.distance)
  test_cams = synthetic.orbit_cameras(s.num_test, s.width, s.height, s.distance, offset=0.37)
  train = synthetic.render_views(gt, train_cams, background)
  test = synthetic.render_views(gt, test_cams, background,
                                names=[f"test_{i:03d}" for i in range(s.num_test)])
  return Dataset(train, test, background, _init_bounds(cfg))


# ------------------------------------------------------------------------- blender


def _blender(cfg, background):
  """A NeRF Synthetic scene (`load_blender`), every `test_every`-th test view."""
  path = resolve_path(cfg.path)
  if not (path / "transforms_train.json").is_file():
    raise FileNotFoundError(
        f"No NeRF Synthetic scene at {path} (config.data.path={cfg.path!r}; relative paths "
        f"are resolved against the working directory). Expected transforms_train.json there.")
  train = load_blender(str(path), "train", downscale=cfg.downscale, background=background)
  test = load_blender(str(path), "test", downscale=cfg.downscale, background=background)
  if cfg.test_every > 1:
    test = test.subset(range(0, len(test), cfg.test_every))
  return Dataset(train, test, background, _init_bounds(cfg))


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


def _split(views, cfg, background, bounds, points=None):
  train, test = holdout_split(len(views), cfg.holdout_every)
  bounds = tuple(np.asarray(b, np.float32) for b in bounds)
  return Dataset(views.subset(train), views.subset(test), background, bounds, points)


def _colmap(cfg, background):
  """A COLMAP capture (`load_colmap`): the held-out split, its sparse points and their box."""
  from mfsample.data.colmap import load_colmap

  views, points = load_colmap(resolve_path(cfg.path), factor=int(cfg.downscale),
                              background=background)
  if len(points):
    bounds = points.box()
  else:  # no points: the box around the cameras
    centers = np.asarray(views.cameras.center, np.float64)
    radius = scene_extent(views.cameras)
    bounds = (centers.mean(0) - radius, centers.mean(0) + radius)
  return _split(views, cfg, background, bounds, points)


def _llff(cfg, background):
  """A forward-facing LLFF capture (`load_llff`): the held-out split, the frusta's box."""
  from mfsample.data.llff import load_llff

  views, depth_bounds = load_llff(resolve_path(cfg.path), factor=int(cfg.downscale))
  return _split(views, cfg, background, frustum_box(views.cameras, depth_bounds))


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


def _scene(cfg, background):
  """A built-in Mitsuba scene (`mfsample.scenes`), captured at its candidate and test
  cameras; the random initial cloud fills the cube around its bounding sphere."""
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
  center = np.asarray(scene.center, np.float32)
  return Dataset(train, test, background, (center - scene.radius, center + scene.radius))


# ------------------------------------------------------------------------- the kinds

DATA_KINDS = {
    "synthetic": DataKind(_synthetic, False, "random Gaussians rendered by mfsample (no files)"),
    "blender": DataKind(_blender, True, "a NeRF Synthetic scene (transforms_*.json)"),
    "scene": DataKind(_scene, False, "a built-in Mitsuba scene, captured on demand"),
    "colmap": DataKind(_colmap, True, "a COLMAP capture (sparse/0, images_N/)"),
    "llff": DataKind(_llff, True, "a forward-facing LLFF capture (poses_bounds.npy)"),
}
# The kinds that are files at `config.data.path`: fixed pools of views.
FILE_KINDS = tuple(name for name, kind in DATA_KINDS.items() if kind.reads_path)


# ------------------------------------------------------------------------- helpers


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
