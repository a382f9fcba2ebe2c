"""The data of a planning run: candidate pool, test views, and (when there is one) an oracle.

* "scene": a built-in Mitsuba scene (`mfsample.scenes`). Candidates and test views are
  captured once (cached on disk); the oracle captures any new pose, so the optimising
  strategies can run.
* "blender": a NeRF Synthetic scene on disk (e.g. lego): candidates = the train split,
  test = the test split. No oracle: only the selection strategies run.
* "colmap", "nerfstudio": a COLMAP or nerfstudio capture (`mfsample.data.load_colmap`,
  `load_nerfstudio`): candidates = the images that are not held out (every
  `holdout_every`-th by name is a test view), its sparse points for round models that start
  from them. No oracle.
* "synthetic": random ground-truth Gaussians rendered by `mfsample.render` (tests and the
  notebook): every pose has a ground truth, no files and no Mitsuba needed.
"""

import math
from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.data.views import Views
from mfsample.planning import poses
from mfsample.renderer import RenderSettings, render
from mfsample.renderer.budget import render_with_budget
from mfsample.train.data import resolve_path


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
  background = tuple(float(c) for c in cfg.background)
  if cfg.kind == "scene":
    return _scene_pool(cfg, background)
  if cfg.kind == "blender":
    return _blender_pool(cfg, background)
  if cfg.kind == "synthetic":
    return _synthetic_pool(cfg, background)
  if cfg.kind in ("colmap", "nerfstudio"):
    return _colmap_pool(cfg, background)
  raise ValueError(f"data.kind must be 'scene', 'blender', 'colmap', 'nerfstudio' or "
                   f"'synthetic', got {cfg.kind!r}")


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


def _blender_pool(cfg, background):
  from mfsample.data import load_blender

  path = resolve_path(cfg.path)
  kw = dict(downscale=int(cfg.downscale), background=background)
  candidates = load_blender(path, "train", **kw)
  test = load_blender(path, "test", **kw)
  if int(cfg.test_every) > 1:
    test = test.subset(np.arange(0, len(test), int(cfg.test_every)))
  lo, hi = cfg.bounds
  return Pool(path.name, candidates, test, background, (np.full(3, lo), np.full(3, hi)),
              poses.SphereSpec.from_cameras(candidates.cameras), None)


def _colmap_pool(cfg, background):
  from mfsample.train.data import load_dataset

  data = load_dataset(_as_training_data(cfg))
  # The cameras of a capture look at the scene, not at the origin: the sphere of the figures
  # is centred on the middle of the sparse points (or of the box without points).
  center = 0.5 * (np.asarray(data.bounds[0], np.float64) + np.asarray(data.bounds[1]))
  return Pool(resolve_path(cfg.path).name, data.train, data.test, background, data.bounds,
              poses.SphereSpec.from_cameras(data.train.cameras, center), None, data.points)


def _as_training_data(cfg):
  """The `data` block of a training config for the capture a planning config names."""
  from mfsample.train.config import default_config

  data = default_config().data
  data.kind = cfg.kind
  data.path = cfg.path
  data.downscale = int(cfg.downscale)
  data.holdout_every = int(cfg.get("holdout_every", 8))
  data.background = tuple(cfg.background)
  return data


def synthetic_scene(num, seed, radius=0.6, sh_degree=0, shape="shell"):
  """Random ground-truth Gaussians: an opaque "shell" (on the sphere of `radius`: every view
  sees one side of a closed surface and none sees through it) or a "cloud" (in the cube
  [-radius, radius]^3)."""
  from mfsample.gaussians import Gaussians
  from mfsample.renderer.sh import rgb_to_sh_dc

  rng = np.random.default_rng(seed)
  k = (sh_degree + 1) ** 2
  sh = np.zeros((num, k, 3), np.float32)
  sh[:, 0] = np.asarray(rgb_to_sh_dc(rng.uniform(0.05, 0.95, (num, 3))))
  if shape == "shell":
    means = rng.normal(size=(num, 3))
    means *= radius / np.linalg.norm(means, axis=1, keepdims=True)
    # Footprints that overlap into a closed surface: about 2x the mean spacing.
    size = 2.0 * radius * np.sqrt(4.0 * np.pi / num)
    scales = np.exp(rng.uniform(np.log(0.6 * size), np.log(size), (num, 3)))
    opacities = rng.uniform(0.85, 0.99, num)
  elif shape == "cloud":
    means = rng.uniform(-radius, radius, (num, 3))
    scales = np.exp(rng.uniform(np.log(0.03), np.log(0.12), (num, 3)))
    opacities = rng.uniform(0.5, 0.95, num)
  else:
    raise ValueError(f"synthetic shape must be 'shell' or 'cloud', got {shape!r}")
  return Gaussians(
      means=jnp.asarray(means, jnp.float32), scales=jnp.asarray(scales, jnp.float32),
      quats=jnp.asarray(rng.normal(size=(num, 4)), jnp.float32),
      opacities=jnp.asarray(opacities, jnp.float32), sh=jnp.asarray(sh))


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


def stack_cameras(cameras):
  """A batched `Camera` from a list of unbatched ones (same image size)."""
  first = cameras[0]
  return Camera(jnp.stack([c.world_to_camera for c in cameras]),
                jnp.stack([c.fx for c in cameras]), jnp.stack([c.fy for c in cameras]),
                jnp.stack([c.cx for c in cameras]), jnp.stack([c.cy for c in cameras]),
                first.width, first.height)
