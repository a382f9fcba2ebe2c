"""The data of a planning run: candidate pool, test views, and (when there is one) an oracle.

`POOL_KINDS` is the one definition of what a planning config's `data.kind` may be:

* "scene": a built-in Mitsuba scene (`mfsample.scenes`). Candidates and test views are
  captured once (cached on disk); the oracle captures any new pose, so the optimising
  strategies can run.
* "synthetic": random ground-truth Gaussians rendered by `mfsample.render` (tests and the
  notebook): every pose has a ground truth, no files and no Mitsuba needed.
* every dataset kind that is files on disk (`mfsample.data.FILE_KINDS`: NeRF Synthetic
  "blender", "colmap", "llff"): candidates = its training views, test = its test views,
  loaded by `mfsample.data.load_dataset`. No oracle: only the selection strategies run. A
  COLMAP capture brings its sparse points, for round models that start from them.
"""

import math
from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.data import FILE_KINDS, load_dataset, resolve_path
from mfsample.data.synthetic import synthetic_scene
from mfsample.data.views import Views
from mfsample.planning import poses
from mfsample.renderer import RenderSettings, render
from mfsample.renderer.budget import render_with_budget


class Pool(NamedTuple):
  """Everything a planning run needs to know about the scene.

  Attributes:
    name: scene name (for tables and figures).
    candidates: `Views` of the candidate pool (images and cameras).
    test: held-out `Views`.
    background: RGB the images are composited on.
    bounds: (low [3], high [3]) box holding the scene: the random initial point cloud and
      the ACP grid live in it.
    sphere: `poses.SphereSpec` of the camera sphere (always set; for a fixed pool it is
      fitted to the candidates and used only for figures).
    oracle: camera -> [H, W, 3] ground-truth image, or None for a fixed pool.
    points: the sparse SfM `PointCloud` of a COLMAP capture (for round models whose
      `model.init_from` is "points"), else None.
  """

  name: str
  candidates: Views
  test: Views
  background: tuple
  bounds: tuple
  sphere: poses.SphereSpec
  oracle: Callable | None
  points: object = None


def make_pool(cfg) -> Pool:
  """The `Pool` that the `data` block of a planning config describes."""
  if cfg.kind not in POOL_KINDS:
    raise ValueError(f"data.kind must be one of {', '.join(map(repr, POOL_KINDS))}, got "
                     f"{cfg.kind!r}")
  background = tuple(float(c) for c in cfg.background)
  if cfg.kind == "scene":
    return _scene_pool(cfg, background)
  if cfg.kind == "synthetic":
    return _synthetic_pool(cfg, background)
  return _file_pool(cfg, background)


def _scene_pool(cfg, background):
  from mfsample import scenes

  scene = scenes.get_scene(cfg.scene)
  cache = str(resolve_path(cfg.cache_dir)) if cfg.get("cache_dir") else None
  w, h = int(cfg.width), int(cfg.height)
  cands = scene.candidate_cameras(w, h, num=int(cfg.num_candidates), seed=int(cfg.pool_seed))
  tests = scene.test_cameras(w, h, num=int(cfg.num_test), seed=int(cfg.pool_seed) + 1)
  kw = dict(spp=int(cfg.spp), cache_dir=cache, background=background)
  candidates = scenes.capture_views(scene, cands, progress=cfg.progress, **kw)
  test = scenes.capture_views(scene, tests, progress=cfg.progress, **kw)

  def oracle(camera):
    return scenes.capture(scene, camera, **kw)[0]

  c, r = np.asarray(scene.center, np.float64), float(scene.radius)
  return Pool(scene.name, candidates, test, background, (c - r, c + r),
              poses.SphereSpec.from_scene(scene, w, h), oracle)


def _file_pool(cfg, background):
  """A fixed pool from a dataset on disk: its training views are the candidates."""
  data = load_dataset(_as_training_data(cfg))
  if cfg.kind == "blender":  # NeRF Synthetic: the cube `cfg.bounds` around the origin
    lo, hi = cfg.bounds
    bounds = (np.full(3, float(lo)), np.full(3, float(hi)))
    sphere = poses.SphereSpec.from_cameras(data.train.cameras)
  else:
    # The cameras of a capture look at the scene, not at the origin: the sphere of the
    # figures is centred on the middle of its box (the sparse points', or the frusta's).
    bounds = data.bounds
    center = 0.5 * (np.asarray(bounds[0], np.float64) + np.asarray(bounds[1]))
    sphere = poses.SphereSpec.from_cameras(data.train.cameras, center)
  return Pool(resolve_path(cfg.path).name, data.train, data.test, background, bounds,
              sphere, None, data.points)


def _as_training_data(cfg):
  """The `data` block of a training config for the dataset a planning config names (its
  `bounds` is the random initial cloud's cube, a training config's `init_bounds`)."""
  from mfsample.train.config import default_config

  data = default_config().data
  data.kind = cfg.kind
  data.path = cfg.path
  data.downscale = int(cfg.downscale)
  data.test_every = int(cfg.test_every)
  data.holdout_every = int(cfg.get("holdout_every", 8))
  data.background = tuple(cfg.background)
  data.init_bounds = tuple(cfg.bounds)
  return data


def _synthetic_pool(cfg, background):
  s = cfg.synthetic
  truth = synthetic_scene(int(s.num_gaussians), int(s.seed), radius=float(s.radius),
                          shape=s.get("shape", "shell"))
  sphere = poses.SphereSpec(radius=float(s.distance), v_range=tuple(s.v_range),
                            fov_x=math.radians(float(s.fov_x_deg)), width=int(cfg.width),
                            height=int(cfg.height))
  bg = jnp.asarray(background, jnp.float32)
  state = {"settings": RenderSettings(max_intersections=1 << 12)}

  def oracle(camera):
    out, state["settings"] = render_with_budget(render, state["settings"], truth, camera,
                                                background=bg)
    return np.asarray(jnp.clip(out.rgb, 0.0, 1.0))

  def views(num, stream):
    uv = poses.random_uv(np.random.default_rng([int(cfg.pool_seed), stream]), num, sphere)
    cams = poses.spherical_camera(jnp.asarray(uv, jnp.float32), sphere)
    images = np.stack([oracle(cams[i]) for i in range(num)])
    return Views(images, cams, names=tuple(f"synthetic-{stream}-{i}" for i in range(num)))

  r = float(s.radius) + 0.2
  return Pool("synthetic", views(int(cfg.num_candidates), 0), views(int(cfg.num_test), 1),
              background, (np.full(3, -r), np.full(3, r)), sphere, oracle)


POOL_KINDS = ("scene", "synthetic") + FILE_KINDS


def stack_cameras(cameras):
  """A batched `Camera` from a list of unbatched ones (same image size)."""
  first = cameras[0]
  return Camera(jnp.stack([c.world_to_camera for c in cameras]),
                jnp.stack([c.fx for c in cameras]), jnp.stack([c.fy for c in cameras]),
                jnp.stack([c.cx for c in cameras]), jnp.stack([c.cy for c in cameras]),
                first.width, first.height)
