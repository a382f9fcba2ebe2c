"""Next-view strategies behind one interface: (model, training cameras, candidates) -> camera.

A `Strategy` names the model it needs (`model_kind`: None, "stochastic" (the rounds'
sampler), a sampler kind ("lowrank", "diagonal", "block"), "deterministic" or "variance"),
whether it may propose poses outside the candidate pool (`new_poses`: such a pose must then
be captured by an oracle), and a pure `select(inputs, key) -> Choice`.

| name          | paper row         | how the next view is chosen                              |
| ------------- | ----------------- | -------------------------------------------------------- |
| random        | -                 | uniformly among the unused candidates                    |
| farthest      | Farthest Point    | max over candidates of the min distance to the training  |
|               |                   | camera centres                                           |
| activenerf    | ActiveNeRF        | max rendered variance (`activenerf`)                     |
| fisher        | FisherRF          | max sum_d H_cand / (H_train + 1e-6) (`baselines.fisher`) |
| acp           | ACP               | max gain of grid coverage + angular uniformity (`acp`)   |
| ours_sel      | Ours (Sel.)       | max U (Eq. 10) over the candidates                       |
| ours_opt_sel  | Ours (Opt. Sel.)  | Adam on -U from the Ours (Sel.) choice (`optimize`)      |
| ours_opt_rnd  | Ours (Opt. Rnd.)  | Adam on -U from a random pose                            |
| ours_opt_best | Ours (Opt. Best)  | Ours (Opt. Sel.), then the pose with the highest U among |
|               |                   | its start and the poses it visited                       |
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import uncertainty as unc
from mfsample.baselines import acp, activenerf, fisher
from mfsample.camera import Camera
from mfsample.planning import optimize, poses
from mfsample.renderer import RenderSettings
from mfsample.sharding import default_num_devices

LABELS = {
    "random": "Random",
    "farthest": "Farthest Point",
    "activenerf": "ActiveNeRF",
    "fisher": "FisherRF",
    "acp": "ACP",
    "ours_sel": "Ours (Sel.)",
    "ours_opt_sel": "Ours (Opt. Sel.)",
    "ours_opt_rnd": "Ours (Opt. Rnd.)",
    "ours_opt_best": "Ours (Opt. Best)",
}
NAMES = tuple(LABELS)
# The rows of the paper's Table 1 (and random): what the main job runs. Ours (Opt. Best) is
# our variant, run by the configs that name it.
TABLE1_NAMES = tuple(n for n in NAMES if n != "ours_opt_best")


class Inputs(NamedTuple):
  """What a strategy sees in one round.

  Attributes:
    model: the model of the strategy's `model_kind`, trained on the current views (a
      `mfsample.model.Model`, or a `baselines.activenerf.VarianceModel`), or None.
    train_cameras: `Camera` [V] of the current training views.
    candidates: `Camera` [C] of the pool.
    available: [C] bool, candidates not selected yet.
    sphere: `poses.SphereSpec` of the camera sphere.
    bounds: (low [3], high [3]) scene box.
    background: RGB tuple.
    settings: {purpose: `RenderSettings`} budgets that sufficed before ("score",
      "optimize"); missing entries start from a small budget and grow.
    max_views: the protocol's largest number of views: per-view arrays are padded to it so
      that one compilation serves every round (None: no padding).
  """

  model: object
  train_cameras: Camera
  candidates: Camera
  available: np.ndarray
  sphere: poses.SphereSpec
  bounds: tuple
  background: tuple
  settings: dict
  max_views: int | None = None


class Choice(NamedTuple):
  """A strategy's answer.

  Attributes:
    index: index into the candidate pool, or None for a new pose.
    camera: the chosen unbatched `Camera`.
    score: the strategy's score of the choice (U, Fisher score, gain, ...; nan if none).
    info: extras: "settings" (updated budgets), "scores" [C], "trajectory", ...
  """

  index: int | None
  camera: Camera
  score: float
  info: dict


class Strategy(NamedTuple):
  """A next-view strategy (see the module docstring)."""

  name: str
  model_kind: str | None
  new_poses: bool
  select: Callable[[Inputs, jax.Array], Choice]

  @property
  def label(self):
    return LABELS.get(self.name, self.name)


# Budgets start small and grow to the next power of two that holds every render: a forward
# render's cost grows with the budget (the tile sort spans all of it), so an oversized
# default would slow down candidate scoring by up to 2x (measured).
_START = RenderSettings(max_intersections=1 << 12)


def _settings(inputs, purpose):
  """The settings that sufficed for `purpose` last time, else the caller's starting settings
  ("start": the round models' renderer, with a small budget), else `_START`."""
  return inputs.settings.get(purpose) or inputs.settings.get("start") or _START


def _small(cameras, cfg):
  """Cameras at 1 / cfg.score_downscale of the image size: candidates are scored there."""
  return poses.downscale_camera(cameras, int(cfg.get("score_downscale", 1)))


def _pick(inputs, scores, extra=None, settings=None):
  """The available candidate with the highest score."""
  scores = np.asarray(scores, np.float64)
  masked = np.where(inputs.available, scores, -np.inf)
  if not np.any(np.isfinite(masked)):
    raise ValueError("no candidate left to select")
  i = int(np.argmax(masked))
  info = {"scores": scores, "settings": dict(inputs.settings, **(settings or {}))}
  info.update(extra or {})
  return Choice(i, inputs.candidates[i], float(scores[i]), info)


def _rng(key):
  return np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel().tolist())


# ------------------------------------------------------------------ model-free


def random_strategy(cfg=None) -> Strategy:
  """Uniformly random among the unused candidates."""
  del cfg

  def select(inputs, key):
    scores = _rng(key).uniform(size=len(inputs.available))
    return _pick(inputs, scores)

  return Strategy("random", None, False, select)


def farthest_strategy(cfg=None) -> Strategy:
  """Farthest point: max over candidates of the min distance to the training centres."""
  del cfg

  def select(inputs, key):
    del key
    cand = np.asarray(inputs.candidates.center, np.float64)
    train = np.asarray(inputs.train_cameras.center, np.float64)
    dist = np.linalg.norm(cand[:, None] - train[None], axis=-1).min(axis=1)
    return _pick(inputs, dist)

  return Strategy("farthest", None, False, select)


def acp_strategy(cfg) -> Strategy:
  """ACP: the candidate that most improves grid coverage and angular uniformity (`acp`).

  cfg fields: resolution (grid cells per axis), bins (direction bins), weight (of the
  uniformity term), near (camera z below which cells are not seen).
  """
  directions = acp.fibonacci_directions(int(cfg.bins))
  memo = {}  # the pool's observations, computed once (host-side, keyed by the poses)

  def select(inputs, key):
    del key
    points = acp.grid_points(*inputs.bounds, resolution=int(cfg.resolution))
    kw = dict(near=float(cfg.near))
    train = acp.observe(inputs.train_cameras, points, directions, **kw)
    pool_key = (np.asarray(inputs.candidates.world_to_camera).tobytes(),
                np.asarray(points).tobytes())
    if pool_key not in memo:
      memo.clear()
      memo[pool_key] = acp.observe(inputs.candidates, points, directions, **kw)
    cands = memo[pool_key]
    gains = acp.acp_gains(train, cands, len(directions), weight=float(cfg.weight))
    return _pick(inputs, gains)

  return Strategy("acp", None, False, select)


# ------------------------------------------------------------------ model-based baselines


def fisher_strategy(cfg) -> Strategy:
  """FisherRF on the deterministic model (`fisher`).

  cfg fields: probes (per candidate), train_probes (per training view), reg (lambda),
  groups (parameter groups), score_downscale (image size divisor while scoring).
  """
  def select(inputs, key):
    out, settings = fisher.fisher_scores(
        inputs.model, _small(inputs.train_cameras, cfg), _small(inputs.candidates, cfg), key,
        settings=_settings(inputs, "score"), background=inputs.background,
        num_probes=int(cfg.probes), train_probes=int(cfg.train_probes), reg=float(cfg.reg),
        groups=tuple(cfg.groups), num_devices=default_num_devices(len(inputs.available)),
        pad_to=inputs.max_views)
    return _pick(inputs, out.values, settings={"score": settings})

  return Strategy("fisher", "deterministic", False, select)


def activenerf_strategy(cfg) -> Strategy:
  """ActiveNeRF-style: the candidate with the largest rendered variance (`baselines.activenerf`).

  cfg fields: score_downscale (image size divisor while scoring); the variance fit's
  fields are read by the runner (`runner.Trainer`).
  """
  def select(inputs, key):
    del key
    scores, settings = activenerf.variance_scores(
        inputs.model, _small(inputs.candidates, cfg), settings=_settings(inputs, "score"),
        num_devices=default_num_devices(len(inputs.available)))
    return _pick(inputs, scores, settings={"score": settings})

  return Strategy("activenerf", "variance", False, select)


# ------------------------------------------------------------------ ours


def _ours_scores(inputs, cfg, cameras=None):
  """U of the candidates (or of `cameras` [B]) as Ours (Sel.) scores them."""
  model = inputs.model
  cameras = inputs.candidates if cameras is None else cameras
  z = unc.uncertainty_z(model, int(cfg.select_samples), int(cfg.z_seed))
  out, settings = unc.score_cameras(
      model, _small(cameras, cfg), z, settings=_settings(inputs, "score"),
      background=jnp.asarray(inputs.background), chunk_size=int(cfg.chunk_size),
      num_devices=default_num_devices(cameras.batch_shape[0]))
  return np.asarray(out.values), settings


def _optimise(inputs, uv0, cfg, opt_cfg, key):
  model = inputs.model
  z = unc.uncertainty_z(model, int(opt_cfg.samples), int(cfg.z_seed))
  down = int(opt_cfg.downscale)
  sphere = inputs.sphere
  opt_sphere = sphere.replace(width=max(sphere.width // down, 1),
                              height=max(sphere.height // down, 1))
  settings = optimize.OptimizeSettings(
      steps=int(opt_cfg.steps), lr=float(opt_cfg.lr), z_drop_step=int(opt_cfg.z_drop_step),
      z_drop_scale=float(opt_cfg.z_drop_scale),
      resample_z=bool(opt_cfg.resample_z))
  result = optimize.optimize_spherical(
      model, jnp.asarray(uv0, jnp.float32), z, sphere=opt_sphere, opt=settings,
      settings=_settings(inputs, "optimize"), background=jnp.asarray(inputs.background),
      key=key)
  camera = poses.spherical_camera(result.params, sphere)  # full resolution
  # `result.values` follow the z scale of each step (U shrinks ~100x after the drop), so
  # the start and the end are measured again with unscaled z: comparable numbers, and the
  # choice's score is U at the chosen pose like every other strategy's.
  ends = poses.spherical_camera(jnp.stack([result.trajectory[0], result.params]), opt_sphere)
  u_ends, score_settings = unc.score_cameras(
      model, ends, z, settings=_settings(inputs, "score"),
      background=jnp.asarray(inputs.background), num_devices=1)
  u_start, u_end = (float(v) for v in np.asarray(u_ends.values))
  info = {"trajectory": np.asarray(result.trajectory), "values": np.asarray(result.values),
          "uv": np.asarray(result.params), "uv0": np.asarray(uv0),
          "u_start": u_start, "u_end": u_end,
          "settings": dict(inputs.settings, optimize=result.settings, score=score_settings)}
  return camera, u_end, info


def ours_sel_strategy(cfg) -> Strategy:
  """Ours (Sel.): the candidate with the highest U (Eq. 10).

  cfg fields: select_samples (M for selection), z_seed (Sobol scrambling seed), chunk_size,
  score_downscale (image size divisor while scoring).
  """
  def select(inputs, key):
    del key
    scores, settings = _ours_scores(inputs, cfg)
    return _pick(inputs, scores, settings={"score": settings})

  return Strategy("ours_sel", "stochastic", False, select)


def _opt_model_kind(opt_cfg):
  return opt_cfg.sampler or "stochastic"


def ours_opt_sel_strategy(cfg, opt_cfg) -> Strategy:
  """Ours (Opt. Sel.): Adam on -U over the camera sphere from the Ours (Sel.) choice.

  opt_cfg fields: samples (M), steps, lr, z_drop_step, z_drop_scale, resample_z (fresh z
  every step), downscale (the optimisation renders at 1/downscale of the image size),
  sampler (the round model's sampler; "": the rounds' own).
  """
  def select(inputs, key):
    _, camera, value, info = _optimise_from_selection(inputs, cfg, opt_cfg, key)
    return Choice(None, camera, value, info)

  return Strategy("ours_opt_sel", _opt_model_kind(opt_cfg), True, select)


def _optimise_from_selection(inputs, cfg, opt_cfg, key):
  """Ours (Sel.)'s choice, and the ascent from it: (start `Choice`, camera, U, info)."""
  scores, settings = _ours_scores(inputs, cfg)
  start = _pick(inputs, scores, settings={"score": settings})
  uv0 = poses.camera_to_uv(start.camera, inputs.sphere.center)
  camera, value, info = _optimise(inputs._replace(settings=start.info["settings"]), uv0,
                                  cfg, opt_cfg, key)
  info.update(start_index=start.index, start_score=start.score, scores=scores)
  return start, camera, value, info


def visited_steps(num_steps, every):
  """Trajectory indices whose poses Ours (Opt. Best) scores: every `every`-th, and the end."""
  if every < 1:
    raise ValueError(f"strategy.optimize.best_every must be >= 1, got {every}")
  return np.unique(np.r_[np.arange(every, num_steps + 1, every), num_steps])


def ours_opt_best_strategy(cfg, opt_cfg) -> Strategy:
  """Ours (Opt. Sel.) that keeps the best pose it saw: never a lower U than Ours (Sel.).

  The ascent follows the gradient of an M = `opt_cfg.samples` estimate of U at a reduced
  size, with z scaled down in its second half; at this scale it often ends at a pose with a
  lower U than its start (docs/camera_planning.md, gradient ascent on the camera). This
  variant scores the start and every `opt_cfg.best_every`-th pose of the trajectory (and its
  end) as Ours (Sel.) scores candidates (M = `cfg.select_samples`, unscaled z, the scoring
  size) and returns the highest: the start candidate itself when no visited pose beats it
  (ties keep the start).
  """
  def select(inputs, key):
    start, _, _, info = _optimise_from_selection(inputs, cfg, opt_cfg, key)
    steps = visited_steps(len(info["trajectory"]) - 1, int(opt_cfg.best_every))
    visited = poses.spherical_camera(jnp.asarray(info["trajectory"][steps]), inputs.sphere)
    u_visited, settings = _ours_scores(inputs._replace(settings=info["settings"]), cfg,
                                       visited)
    info.update(visited_steps=steps, u_visited=u_visited,
                settings=dict(info["settings"], score=settings))
    best = int(np.argmax(u_visited))
    if not u_visited[best] > start.score:
      info["kept_step"] = 0
      return Choice(start.index, start.camera, start.score, info)
    info["kept_step"] = int(steps[best])
    return Choice(None, visited[best], float(u_visited[best]), info)

  return Strategy("ours_opt_best", _opt_model_kind(opt_cfg), True, select)


def ours_opt_rnd_strategy(cfg, opt_cfg) -> Strategy:
  """Ours (Opt. Rnd.): Adam on -U over the camera sphere from a random pose."""
  def select(inputs, key):
    uv0 = poses.random_uv(_rng(key), 1, inputs.sphere)[0]
    # Fresh z (resample_z) from a key derived from the start's: the start is unchanged.
    camera, value, info = _optimise(inputs, uv0, cfg, opt_cfg, jax.random.fold_in(key, 1))
    return Choice(None, camera, value, info)

  return Strategy("ours_opt_rnd", _opt_model_kind(opt_cfg), True, select)


def make_strategy(name, config) -> Strategy:
  """The strategy `name` (one of `NAMES`) with its settings from a planning config."""
  s = config.strategy
  makers = {
      "random": lambda: random_strategy(),
      "farthest": lambda: farthest_strategy(),
      "acp": lambda: acp_strategy(s.acp),
      "fisher": lambda: fisher_strategy(s.fisher),
      "activenerf": lambda: activenerf_strategy(s.activenerf),
      "ours_sel": lambda: ours_sel_strategy(s.ours),
      "ours_opt_sel": lambda: ours_opt_sel_strategy(s.ours, s.optimize),
      "ours_opt_rnd": lambda: ours_opt_rnd_strategy(s.ours, s.optimize),
      "ours_opt_best": lambda: ours_opt_best_strategy(s.ours, s.optimize),
  }
  if name not in makers:
    raise ValueError(f"unknown strategy {name!r}; known: {', '.join(NAMES)}")
  return makers[name]()
