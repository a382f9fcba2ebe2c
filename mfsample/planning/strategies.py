"""Next-view strategies behind one interface: (model, training cameras, candidates) -> camera.

`STRATEGIES` is the registry: every strategy's name, label, maker and random stream, read
by the config's validator, the tables and the docs.

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

import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import settings_checks as sc
from mfsample import streams
from mfsample import view_uncertainty as unc
from mfsample.baselines import acp, activenerf, fisher
from mfsample.camera import Camera
from mfsample.groups import GROUPS
from mfsample.planning import optimize, poses
from mfsample.renderer import RenderSettings
from mfsample.samplers import STOCHASTIC_KINDS, sample_z
from mfsample.sharding import default_num_devices

# ------------------------------------------------------------------ settings


@dataclasses.dataclass(frozen=True)
class OursSettings:
  """Ours (Sel.): U of every candidate (Eq. 10).

  Attributes:
    select_samples: M of the candidates' U (paper: 2).
    z_seed: Sobol scrambling seed of the U samples (authors' code: 6174).
    chunk_size: candidates vmapped together (1: sequential, cheapest on a CPU).
    score_downscale: candidates are scored at 1 / this of the image size.
  """

  select_samples: int = 8
  z_seed: int = 6174
  chunk_size: int = 1
  score_downscale: int = 2

  def __post_init__(self):
    sc.check_int("OursSettings.select_samples", self.select_samples, minimum=2)  # U of one: 0
    sc.check_int("OursSettings.z_seed", self.z_seed, minimum=0, maximum=2**32 - 1)
    sc.check_int("OursSettings.chunk_size", self.chunk_size, minimum=1)
    sc.check_int("OursSettings.score_downscale", self.score_downscale, minimum=1)


@dataclasses.dataclass(frozen=True)
class AscentSettings:
  """The optimising strategies: Adam on -U over the camera sphere (paper Sec. 4.4).

  Attributes:
    samples: M during the ascent (paper: 2).
    steps, lr, z_drop_step, z_drop_scale, resample_z: `optimize.OptimizeSettings`'.
    downscale: the ascent renders at 1 / this of the image size.
    sampler: the round model's sampler ("": the rounds' own; a stochastic kind).
    best_every: Ours (Opt. Best) scores every this-th pose of the ascent (and its end).
  """

  samples: int = 2
  steps: int = 60
  lr: float = 3.3e-3
  z_drop_step: int = 30
  z_drop_scale: float = 0.1
  downscale: int = 2
  resample_z: bool = False
  sampler: str = ""
  best_every: int = 10

  def __post_init__(self):
    sc.check_int("AscentSettings.samples", self.samples, minimum=2)
    sc.check_int("AscentSettings.steps", self.steps, minimum=0)
    # 0: the pose stays at selection's choice (the optimiser's ablation).
    sc.check_float("AscentSettings.lr", self.lr, minimum=0.0)
    sc.check_int("AscentSettings.z_drop_step", self.z_drop_step, minimum=0)
    sc.check_float("AscentSettings.z_drop_scale", self.z_drop_scale, above=0.0, maximum=1.0)
    sc.check_int("AscentSettings.downscale", self.downscale, minimum=1)
    sc.check_bool("AscentSettings.resample_z", self.resample_z)
    sc.check_choice("AscentSettings.sampler", self.sampler, ("",) + STOCHASTIC_KINDS)
    sc.check_int("AscentSettings.best_every", self.best_every, minimum=1)

  def optimize_settings(self):
    """The `optimize.OptimizeSettings` of the ascent."""
    return optimize.OptimizeSettings(steps=self.steps, lr=self.lr,
                                     z_drop_step=self.z_drop_step,
                                     z_drop_scale=self.z_drop_scale, resample_z=self.resample_z)


@dataclasses.dataclass(frozen=True)
class FisherSettings:
  """FisherRF (`baselines.fisher`).

  Attributes:
    probes: Rademacher probes (backward passes) per candidate.
    train_probes: probes per training view (H_train is in a denominator).
    reg: lambda of sum H_cand / (H_train + lambda).
    groups: the parameter groups (FisherRF leaves out rotations).
    score_downscale: candidates are scored at 1 / this of the image size.
  """

  probes: int = 1
  train_probes: int = 8
  reg: float = 1e-6
  groups: tuple = ("means", "log_scales", "opacity_logits", "sh_dc", "sh_rest")
  score_downscale: int = 2

  def __post_init__(self):
    sc.check_int("FisherSettings.probes", self.probes, minimum=1)
    sc.check_int("FisherSettings.train_probes", self.train_probes, minimum=1)
    sc.check_float("FisherSettings.reg", self.reg, above=0.0)
    sc.set_field(self, "groups", sc.check_names("FisherSettings.groups", self.groups, GROUPS,
                                                min_length=1))
    sc.check_int("FisherSettings.score_downscale", self.score_downscale, minimum=1)


@dataclasses.dataclass(frozen=True)
class ActiveNerfSettings:
  """ActiveNeRF-style rendered variance (`baselines.activenerf`).

  Attributes:
    steps, lr: Adam steps and rate of the per-Gaussian log-variance fit (one view each).
    prior_var: variance of Gaussians no view constrains.
    beta_min: variance floor of every pixel.
    prior_weight: weight of the quadratic prior on the log-variance.
    score_downscale: candidates are scored at 1 / this of the image size.
  """

  steps: int = 40
  lr: float = 0.05
  prior_var: float = 0.05
  beta_min: float = 1e-3
  prior_weight: float = 1e-3
  score_downscale: int = 2

  def __post_init__(self):
    sc.check_int("ActiveNerfSettings.steps", self.steps, minimum=0)
    for name in ("lr", "prior_var", "beta_min"):
      sc.check_float(f"ActiveNerfSettings.{name}", getattr(self, name), above=0.0)
    sc.check_float("ActiveNerfSettings.prior_weight", self.prior_weight, minimum=0.0)
    sc.check_int("ActiveNerfSettings.score_downscale", self.score_downscale, minimum=1)


@dataclasses.dataclass(frozen=True)
class AcpSettings:
  """ACP (`baselines.acp`): grid coverage and angular uniformity.

  Attributes:
    resolution: grid cells per axis (Kopanas & Drettakis: 32^3).
    bins: direction bins (Fibonacci sphere).
    weight: weight of angular uniformity against coverage.
    near: cells nearer than this (camera z) are not observed.
  """

  resolution: int = 32
  bins: int = 64
  weight: float = 1.0
  near: float = 0.2

  def __post_init__(self):
    sc.check_int("AcpSettings.resolution", self.resolution, minimum=1)
    sc.check_int("AcpSettings.bins", self.bins, minimum=1)
    sc.check_float("AcpSettings.weight", self.weight, minimum=0.0)
    sc.check_float("AcpSettings.near", self.near, minimum=0.0)


@dataclasses.dataclass(frozen=True)
class StrategySettings:
  """Every strategy's settings (the planning config's `strategy` block, typed)."""

  ours: OursSettings = OursSettings()
  optimize: AscentSettings = AscentSettings()
  fisher: FisherSettings = FisherSettings()
  activenerf: ActiveNerfSettings = ActiveNerfSettings()
  acp: AcpSettings = AcpSettings()


class Renders(NamedTuple):
  """The render settings that sufficed before for a strategy's two kinds of render (None:
  not known yet; the strategy starts from `Inputs.start` and grows the budget)."""

  score: RenderSettings | None = None  # scoring candidates: U, FisherRF, ActiveNeRF
  optimize: RenderSettings | None = None  # the camera ascent's renders


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
    renders: `Renders` that sufficed before; unknown ones start from `start` and grow.
    start: `RenderSettings` of a first render (the round models' renderer, a small budget).
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
  renders: Renders = Renders()
  start: RenderSettings | None = None
  max_views: int | None = None


class Choice(NamedTuple):
  """A strategy's answer.

  Attributes:
    index: index into the candidate pool, or None for a new pose.
    camera: the chosen unbatched `Camera`.
    score: the strategy's score of the choice (U, Fisher score, gain, ...; nan if none).
    info: extras: "scores" [C], "trajectory", ...
    renders: the inputs' `Renders`, with those the strategy grew.
  """

  index: int | None
  camera: Camera
  score: float
  info: dict
  renders: Renders = Renders()


class Strategy(NamedTuple):
  """A next-view strategy (see the module docstring)."""

  name: str
  model_kind: str | None
  new_poses: bool
  select: Callable[[Inputs, jax.Array], Choice]

  @property
  def label(self):
    return STRATEGIES[self.name].label if self.name in STRATEGIES else self.name


# Budgets start small and grow to the next power of two that holds every render: a forward
# render's cost grows with the budget (the tile sort spans all of it), so an oversized
# default would slow down candidate scoring by up to 2x (measured).
_START = RenderSettings(max_intersections=1 << 12)


def _settings(inputs, kind):
  """The settings that sufficed for the renders of `kind` ("score", "optimize") last time,
  else the caller's starting settings (the round models' renderer, with a small budget), else
  `_START`."""
  return getattr(inputs.renders, kind) or inputs.start or _START


def _small(cameras, downscale):
  """Cameras at 1 / `downscale` of the image size: candidates are scored there."""
  return poses.downscale_camera(cameras, int(downscale))


def _pick(inputs, scores, extra=None, **grown):
  """The available candidate with the highest score (`grown`: budgets that sufficed)."""
  scores = np.asarray(scores, np.float64)
  masked = np.where(inputs.available, scores, -np.inf)
  if not np.any(np.isfinite(masked)):
    raise ValueError("no candidate left to select")
  i = int(np.argmax(masked))
  info = {"scores": scores}
  info.update(extra or {})
  return Choice(i, inputs.candidates[i], float(scores[i]), info,
                inputs.renders._replace(**grown))


def _rng(key):
  return np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel().tolist())


# ------------------------------------------------------------------ model-free


def random_strategy() -> Strategy:
  """Uniformly random among the unused candidates."""

  def select(inputs, key):
    scores = _rng(key).uniform(size=len(inputs.available))
    return _pick(inputs, scores)

  return Strategy("random", None, False, select)


def farthest_strategy() -> Strategy:
  """Farthest point: max over candidates of the min distance to the training centres."""

  def select(inputs, key):
    del key
    cand = np.asarray(inputs.candidates.center, np.float64)
    train = np.asarray(inputs.train_cameras.center, np.float64)
    dist = np.linalg.norm(cand[:, None] - train[None], axis=-1).min(axis=1)
    return _pick(inputs, dist)

  return Strategy("farthest", None, False, select)


def acp_strategy(cfg: AcpSettings) -> Strategy:
  """ACP: the candidate that most improves grid coverage and angular uniformity (`acp`)."""
  directions = acp.fibonacci_directions(cfg.bins)
  memo = {}  # the pool's observations, computed once (host-side, keyed by the poses)

  def select(inputs, key):
    del key
    points = acp.grid_points(*inputs.bounds, resolution=cfg.resolution)
    kw = dict(near=cfg.near)
    train = acp.observe(inputs.train_cameras, points, directions, **kw)
    pool_key = (np.asarray(inputs.candidates.world_to_camera).tobytes(),
                np.asarray(points).tobytes())
    if pool_key not in memo:
      memo.clear()
      memo[pool_key] = acp.observe(inputs.candidates, points, directions, **kw)
    cands = memo[pool_key]
    gains = acp.acp_gains(train, cands, len(directions), weight=cfg.weight)
    return _pick(inputs, gains)

  return Strategy("acp", None, False, select)


# ------------------------------------------------------------------ model-based baselines


def fisher_strategy(cfg: FisherSettings) -> Strategy:
  """FisherRF on the deterministic model (`fisher`)."""
  def select(inputs, key):
    out, settings = fisher.fisher_scores(
        inputs.model, _small(inputs.train_cameras, cfg.score_downscale),
        _small(inputs.candidates, cfg.score_downscale), key,
        settings=_settings(inputs, "score"), background=inputs.background,
        num_probes=cfg.probes, train_probes=cfg.train_probes, reg=cfg.reg, groups=cfg.groups,
        num_devices=default_num_devices(len(inputs.available)), pad_to=inputs.max_views)
    return _pick(inputs, out.values, score=settings)

  return Strategy("fisher", "deterministic", False, select)


def activenerf_strategy(cfg: ActiveNerfSettings) -> Strategy:
  """ActiveNeRF-style: the candidate with the largest rendered variance (`baselines.activenerf`).

  The variance fit's settings are the runner's (`runner.Trainer`).
  """
  def select(inputs, key):
    del key
    scores, settings = activenerf.variance_scores(
        inputs.model, _small(inputs.candidates, cfg.score_downscale),
        settings=_settings(inputs, "score"),
        num_devices=default_num_devices(len(inputs.available)))
    return _pick(inputs, scores, score=settings)

  return Strategy("activenerf", "variance", False, select)


# ------------------------------------------------------------------ ours


def _ours_scores(inputs, cfg: OursSettings, cameras=None):
  """U of the candidates (or of `cameras` [B]) as Ours (Sel.) scores them."""
  model = inputs.model
  cameras = inputs.candidates if cameras is None else cameras
  z = sample_z(model, cfg.select_samples, seed=cfg.z_seed)
  out, settings = unc.score_cameras(
      model, _small(cameras, cfg.score_downscale), z, settings=_settings(inputs, "score"),
      background=jnp.asarray(inputs.background), chunk_size=cfg.chunk_size,
      num_devices=default_num_devices(cameras.batch_shape[0]))
  return np.asarray(out.values), settings


def _optimise(inputs, uv0, cfg: OursSettings, opt_cfg: AscentSettings, key):
  model = inputs.model
  z = sample_z(model, opt_cfg.samples, seed=cfg.z_seed)
  down = opt_cfg.downscale
  sphere = inputs.sphere
  opt_sphere = sphere.replace(width=max(sphere.width // down, 1),
                              height=max(sphere.height // down, 1))
  result = optimize.optimize_spherical(
      model, jnp.asarray(uv0, jnp.float32), z, sphere=opt_sphere,
      opt=opt_cfg.optimize_settings(),
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
          "u_start": u_start, "u_end": u_end}
  return camera, u_end, info, inputs.renders._replace(optimize=result.settings,
                                                       score=score_settings)


def ours_sel_strategy(cfg: OursSettings) -> Strategy:
  """Ours (Sel.): the candidate with the highest U (Eq. 10)."""
  def select(inputs, key):
    del key
    scores, settings = _ours_scores(inputs, cfg)
    return _pick(inputs, scores, score=settings)

  return Strategy("ours_sel", "stochastic", False, select)


def _opt_model_kind(opt_cfg: AscentSettings):
  return opt_cfg.sampler or "stochastic"


def ours_opt_sel_strategy(cfg: OursSettings, opt_cfg: AscentSettings) -> Strategy:
  """Ours (Opt. Sel.): Adam on -U over the camera sphere from the Ours (Sel.) choice."""
  def select(inputs, key):
    _, camera, value, info, renders = _optimise_from_selection(inputs, cfg, opt_cfg, key)
    return Choice(None, camera, value, info, renders)

  return Strategy("ours_opt_sel", _opt_model_kind(opt_cfg), True, select)


def _optimise_from_selection(inputs, cfg, opt_cfg, key):
  """Ours (Sel.)'s choice, and the ascent from it: (start `Choice`, camera, U, info,
  renders)."""
  scores, settings = _ours_scores(inputs, cfg)
  start = _pick(inputs, scores, score=settings)
  uv0 = poses.camera_to_uv(start.camera, inputs.sphere.center)
  camera, value, info, renders = _optimise(inputs._replace(renders=start.renders), uv0, cfg,
                                           opt_cfg, key)
  info.update(start_index=start.index, start_score=start.score, scores=scores)
  return start, camera, value, info, renders


def visited_steps(num_steps, every):
  """Trajectory indices whose poses Ours (Opt. Best) scores: every `every`-th, and the end."""
  if every < 1:
    raise ValueError(f"strategy.optimize.best_every must be >= 1, got {every}")
  return np.unique(np.r_[np.arange(every, num_steps + 1, every), num_steps])


def ours_opt_best_strategy(cfg: OursSettings, opt_cfg: AscentSettings) -> Strategy:
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
    start, _, _, info, renders = _optimise_from_selection(inputs, cfg, opt_cfg, key)
    steps = visited_steps(len(info["trajectory"]) - 1, opt_cfg.best_every)
    visited = poses.spherical_camera(jnp.asarray(info["trajectory"][steps]), inputs.sphere)
    u_visited, settings = _ours_scores(inputs._replace(renders=renders), cfg, visited)
    renders = renders._replace(score=settings)
    info.update(visited_steps=steps, u_visited=u_visited)
    best = int(np.argmax(u_visited))
    if not u_visited[best] > start.score:
      info["kept_step"] = 0
      return Choice(start.index, start.camera, start.score, info, renders)
    info["kept_step"] = int(steps[best])
    return Choice(None, visited[best], float(u_visited[best]), info, renders)

  return Strategy("ours_opt_best", _opt_model_kind(opt_cfg), True, select)


def ours_opt_rnd_strategy(cfg: OursSettings, opt_cfg: AscentSettings) -> Strategy:
  """Ours (Opt. Rnd.): Adam on -U over the camera sphere from a random pose."""
  def select(inputs, key):
    uv0 = poses.random_uv(_rng(key), 1, inputs.sphere)[0]
    # Fresh z (resample_z) from a key derived from the start's: the start is unchanged.
    camera, value, info, renders = _optimise(inputs, uv0, cfg, opt_cfg,
                                             jax.random.fold_in(key, 1))
    return Choice(None, camera, value, info, renders)

  return Strategy("ours_opt_rnd", _opt_model_kind(opt_cfg), True, select)


class StrategySpec(NamedTuple):
  """A registered strategy.

  Attributes:
    label: its name in tables and figures (the paper's row).
    make: `StrategySettings` -> `Strategy`.
    stream: its random stream (`mfsample.streams`): fixed with the strategy, not its place.
    table1: whether the main job runs it (a row of the paper's Table 1, or random).
  """

  label: str
  make: Callable
  stream: int
  table1: bool = True


STRATEGIES = {
    "random": StrategySpec("Random", lambda s: random_strategy(), 0),
    "farthest": StrategySpec("Farthest Point", lambda s: farthest_strategy(), 1),
    "activenerf": StrategySpec("ActiveNeRF", lambda s: activenerf_strategy(s.activenerf), 2),
    "fisher": StrategySpec("FisherRF", lambda s: fisher_strategy(s.fisher), 3),
    "acp": StrategySpec("ACP", lambda s: acp_strategy(s.acp), 4),
    "ours_sel": StrategySpec("Ours (Sel.)", lambda s: ours_sel_strategy(s.ours), 5),
    "ours_opt_sel": StrategySpec("Ours (Opt. Sel.)",
                                 lambda s: ours_opt_sel_strategy(s.ours, s.optimize), 6),
    "ours_opt_rnd": StrategySpec("Ours (Opt. Rnd.)",
                                 lambda s: ours_opt_rnd_strategy(s.ours, s.optimize), 7),
    # Our variant, run by the configs that name it.
    "ours_opt_best": StrategySpec("Ours (Opt. Best)",
                                  lambda s: ours_opt_best_strategy(s.ours, s.optimize), 8,
                                  table1=False),
}
streams.check_streams(STRATEGIES, "camera strategies")
NAMES = tuple(STRATEGIES)
# The rows of the paper's Table 1 (and random): what the main job runs.
TABLE1_NAMES = tuple(name for name, spec in STRATEGIES.items() if spec.table1)


def make_strategy(name, settings: StrategySettings = StrategySettings()) -> Strategy:
  """The strategy `name` (one of `NAMES`) with its `settings`."""
  if name not in STRATEGIES:
    raise ValueError(f"unknown strategy {name!r}; known: {', '.join(NAMES)}")
  return STRATEGIES[name].make(settings)


def strategy_key(seed, name, round_index):
  """The PRNG key of strategy `name` choosing the view of round `round_index` for `seed`."""
  return streams.stream_key(seed, STRATEGIES[name].stream, round_index)
