"""The active camera planning protocol (paper Sec. 5.1): pure steps, thin loop.

For every seed and strategy:

1. start from one candidate view (`initial_index`);
2. each round trains a fresh model of the strategy's kind on the current views
   (`config.round_train`, `train_on_views`), asks the strategy for the next camera, and adds
   that view: the pool image for a candidate, an oracle capture for a new pose;
3. at each count in `config.eval_views` (5 and 10) a plain deterministic model is trained
   from scratch on the first views (`config.final_train`) and evaluated on the held-out
   test views (PSNR / SSIM / LPIPS).

Results are written per (strategy, seed) as soon as they finish (`runs/*.json`), so a
killed run resumes without redoing finished work; `results.json` and `table.md` aggregate
them, `cameras.png` and `landscape.png` show the chosen cameras and the uncertainty
landscape (paper Fig. 7).

Rounds either re-initialise the model (the authors' code) or continue training it on the
enlarged view set (the paper's text: one run, a camera added every so many steps):
`config.rounds.warm_start`. Identical trainings (the same kind, seed and views, e.g. the
first round of the three "Ours" variants) are shared through an in-memory cache.
"""

import collections
import functools
import hashlib
import json
import os
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import metrics as metrics_lib
from mfsample import uncertainty as unc
from mfsample import workdir as workdir_lib
from mfsample._json import atomic_path, write_json, write_text
from mfsample.data._io import area_downscale
from mfsample.data.views import Views
from mfsample.model import mean_gaussians
from mfsample.planning import figures, poses, strategies, tables, training, variance, workdirs
from mfsample.planning.config import validate
from mfsample.planning.pool import Pool, make_pool, stack_cameras
from mfsample.renderer import render
from mfsample.renderer.budget import render_with_budget
from mfsample.viewer.rounds import record_rounds


class Selected(NamedTuple):
  """One view of a trajectory.

  Attributes:
    index: candidate index, or None for a captured new pose.
    camera: unbatched `Camera`.
    image: [H, W, 3].
    score: the strategy's score of the choice (nan for the initial view).
    seconds: wall-clock of the round that chose it (training + selection + capture).
    info: json-able extras (optimisation start / end, ...).
  """

  index: int | None
  camera: object
  image: np.ndarray
  score: float
  seconds: float
  info: dict


# ------------------------------------------------------------------ pure pieces


def candidate_view(pool: Pool, index) -> Selected:
  """Candidate `index` of `pool` as a view of a trajectory (no score, no round time)."""
  cands = pool.candidates
  return Selected(int(index), cands.cameras[int(index)], np.asarray(cands.images[int(index)]),
                  float("nan"), 0.0, {})


def initial_index(config, seed, num_candidates):
  """The first view: `config.initial_view`, or (if < 0) a seeded random candidate."""
  if int(config.initial_view) >= 0:
    if int(config.initial_view) >= num_candidates:
      raise ValueError(f"config.initial_view = {config.initial_view}: the pool has "
                       f"{num_candidates} candidates (indices 0 .. {num_candidates - 1})")
    return int(config.initial_view)
  return int(np.random.default_rng([int(seed), 5]).integers(num_candidates))


def view_key(sel: Selected):
  """A hashable identity of a view (its candidate index or its pose)."""
  if sel.index is not None:
    return ("c", int(sel.index))
  w2c = np.round(np.asarray(sel.camera.world_to_camera, np.float64), 6) + 0.0
  return ("p", hashlib.sha1(w2c.tobytes()).hexdigest()[:16])


def as_views(selected, downscale=1) -> Views:
  """`Views` of a list of `Selected`, optionally `downscale` times smaller (box filter)."""
  images = np.stack([s.image for s in selected]).astype(np.float32)
  cameras = stack_cameras([s.camera for s in selected])
  if downscale > 1:
    images = np.stack([area_downscale(image, downscale) for image in images])
    cameras = poses.downscale_camera(cameras, downscale)
  return Views(images, cameras, names=tuple(str(view_key(s)) for s in selected))


def round_config(config, kind):
  """The training config of the rounds for a model kind (a copy).

  "stochastic" keeps the config's sampler; "lowrank", "diagonal" or "block" replace it.

  Re-initialised rounds (the authors' code) train `rounds.steps` steps each. With
  `rounds.warm_start` (the paper's text: one run, a camera added every so many steps) the
  schedules span the whole run: `rounds.first_steps` + (max_views - 2) * `rounds.steps`.
  """
  cfg = config.round_train.copy_and_resolve_references()
  r = config.rounds
  with cfg.unlocked():
    if kind in ("deterministic", "variance"):
      cfg.sampler.kind = "deterministic"
    elif kind in ("lowrank", "diagonal", "block"):  # a strategy that names its sampler
      cfg.sampler.kind = kind
    if r.warm_start:
      cfg.train.num_steps = int(r.first_steps) + (int(config.max_views) - 2) * int(r.steps)
    else:
      cfg.train.num_steps = int(r.steps)
  return cfg


class Trainer:
  """Trains (and caches) models for the rounds and the final evaluation.

  Host-side bookkeeping only: the cache maps (kind, seed, view keys) to trained models, and
  `settings` remembers the render budgets that sufficed, so later calls start from them.
  """

  def __init__(self, config, pool: Pool, cache_size=24):
    self.config = config
    self.pool = pool
    self.cache = collections.OrderedDict()
    self.cache_size = cache_size
    self.settings = {}
    self.train_seconds = 0.0

  def _cached(self, key, make):
    if key in self.cache:
      self.cache.move_to_end(key)
      return self.cache[key]
    value = make()
    self.cache[key] = value
    while len(self.cache) > self.cache_size:
      self.cache.popitem(last=False)
    return value

  def _train(self, cfg, selected, seed, budget, downscale=1, state=None, stop_at=None):
    """Trains `cfg` on the `selected` views; the render budget that sufficed is kept under
    `budget` for the next call.

    A fixed-shape model trains padded to `max_views` image slots (one compilation for every
    view count; `state` / `stop_at` continue one, see `training.train_on_views`); a model
    that densifies changes shape anyway and trains with `mfsample.train.train` as it is.
    """
    views = as_views(selected, downscale)
    t0 = time.perf_counter()
    if training.densifies(cfg):
      # Every densified model compiles its own shapes (view count, capacity buckets), and
      # XLA:CPU keeps each executable's code mapped: a lego run exhausted the process's
      # memory maps (vm.max_map_count, 65530) in its second seed. What an earlier model
      # compiled has other shapes than this one's, but for a few small functions that
      # recompile in seconds against a model's minutes, so the caches go first. The clear
      # is process-wide: other compiled functions of the caller recompile on next use.
      jax.clear_caches()
      trained = training.train_densified(cfg, views, seed=seed, bounds=self.pool.bounds,
                                         settings=self.settings.get(budget),
                                         points=self.pool.points)
    else:
      trained = training.train_on_views(cfg, views, seed=seed, bounds=self.pool.bounds,
                                        pad_to=self.config.max_views,
                                        settings=self.settings.get(budget), state=state,
                                        stop_at=stop_at, points=self.pool.points)
    self.train_seconds += time.perf_counter() - t0
    self.settings[budget] = trained.settings
    return trained

  def round_state(self, base, selected, seed):
    """`training.Trained` of a model of kind `base` after the round on `selected` (cached).

    Warm start: the previous round's state (recursively) continued for `rounds.steps` more
    steps on the larger view set; otherwise a fresh model trained `rounds.steps` steps,
    with densification where the round config asks for it (the authors' rounds).
    """
    keys = tuple(view_key(s) for s in selected)
    r = self.config.rounds

    def make():
      cfg = round_config(self.config, base)
      state, stop_at = None, int(r.steps)
      if training.densifies(cfg):
        if r.warm_start:
          raise ValueError("rounds.warm_start continues one padded state, which cannot "
                           "densify: set round_train.densify.start >= rounds.steps")
      elif r.warm_start:
        stop_at = int(r.first_steps)
        if len(selected) > 1:
          prev = self.round_state(base, selected[:-1], seed)
          state, stop_at = prev.state, int(prev.state.step) + int(r.steps)
      return self._train(cfg, selected, seed, ("round", base), int(r.downscale), state,
                         stop_at)

    return self._cached(("round", base, seed, keys), make)

  def round_model(self, kind, selected, seed):
    """The model of `kind` for the round on the `selected` views (cached)."""
    base = "deterministic" if kind == "variance" else kind
    if kind != "variance":
      return self.round_state(base, selected, seed).model
    keys = tuple(view_key(s) for s in selected)

    def make():
      trained = self.round_state(base, selected, seed)
      a = self.config.strategy.activenerf
      t0 = time.perf_counter()
      vmodel, _ = variance.fit_variance(
          trained.model, as_views(selected, int(self.config.rounds.downscale)),
          settings=trained.settings,
          background=self.pool.background, steps=int(a.steps), lr=float(a.lr),
          prior_var=float(a.prior_var), beta_min=float(a.beta_min),
          prior_weight=float(a.prior_weight), seed=seed, pad_to=self.config.max_views)
      self.train_seconds += time.perf_counter() - t0
      return vmodel

    return self._cached(("variance", seed, keys), make)

  def final_model(self, selected, seed):
    """The plain model of the final evaluation, trained on `selected` (cached)."""
    keys = tuple(view_key(s) for s in selected)

    def make():
      return self._train(self.config.final_train, selected, seed, "final").model

    return self._cached(("final", seed, keys), make)


@functools.partial(jax.jit, static_argnames=("settings",))
def render_views(model, cameras, background, *, settings):
  """[V, H, W, 3] renders of the mean model (one after another: cheap budget skipping)."""
  gaussians = mean_gaussians(model)

  def one(camera):
    out = render(gaussians, camera, background=background, settings=settings)
    return jnp.clip(out.rgb, 0.0, 1.0), out.stats

  return jax.lax.map(one, cameras)


@jax.jit
def _image_metrics(pred, gt):
  """Per-view PSNR and SSIM of [V, H, W, 3] batches (`mfsample.metrics`)."""
  return metrics_lib.psnr(pred, gt), metrics_lib.ssim(pred, gt)


def evaluate_model(model, views: Views, *, background, settings, lpips_fn=None):
  """Test metrics of a model's mean: {"psnr", "ssim", "lpips"}, means over `views`.

  All views are rendered in one jitted call and scored in batches (PSNR and SSIM of
  `mfsample.metrics`, LPIPS of `lpips_fn`), instead of one host round trip per view.

  Returns:
    (metrics dict, settings that sufficed).
  """
  bg = jnp.asarray(background, jnp.float32)
  (pred, _), settings = render_with_budget(render_views, settings, model, views.cameras, bg,
                                          stats_of=lambda out: out[1])
  gt = jnp.asarray(views.images, jnp.float32)
  psnr, ssim = _image_metrics(pred, gt)
  out = {"psnr": float(np.mean(psnr)), "ssim": float(np.mean(ssim)), "lpips": None}
  if lpips_fn is not None:
    out["lpips"] = float(np.mean(np.asarray(lpips_fn(pred, gt))))
  return out, settings


def scoring_start(config):
  """Starting settings of the strategies' renders (scores, ascents): the round models'
  renderer (`round_train.render`: footprint rule, compositor) with a small budget, grown
  on overflow."""
  from mfsample.train.loop import render_settings

  return render_settings(config.round_train.render).holding_budget(1 << 12)


def choose_next(strategy, pool: Pool, config, seed, trainer: Trainer, budgets, selected,
                available):
  """One round of a strategy: its choice of the next view after the views `selected`.

  Trains (or takes from `trainer`'s cache) the round model the strategy needs and draws its
  random key from the seed, the strategy and the round, so a round can be replayed alone.

  Args:
    strategy: `strategies.Strategy`.
    pool: `Pool`.
    config: planning config.
    seed: int.
    trainer: `Trainer`.
    budgets: {purpose: RenderSettings} shared across strategies; updated in place.
    selected: list of `Selected`, the current views.
    available: [C] bool, candidates not selected yet.

  Returns:
    the strategy's `strategies.Choice`.
  """
  model = None
  if strategy.model_kind is not None:
    model = trainer.round_model(strategy.model_kind, selected, seed)
  inputs = strategies.Inputs(
      model=model, train_cameras=stack_cameras([s.camera for s in selected]),
      candidates=pool.candidates.cameras, available=available, sphere=pool.sphere,
      bounds=pool.bounds, background=pool.background,
      settings={"start": scoring_start(config), **budgets},
      max_views=int(config.max_views))
  key = jax.random.fold_in(jax.random.PRNGKey(int(seed)), strategies.NAMES.index(
      strategy.name) if strategy.name in strategies.NAMES else 99)
  choice = strategy.select(inputs, jax.random.fold_in(key, len(selected)))
  budgets.update(choice.info.get("settings", {}))
  return choice


def plan_views(strategy, pool: Pool, config, seed, trainer: Trainer, budgets, on_round=None):
  """Runs one strategy for one seed up to `config.max_views` views.

  Args:
    strategy: `strategies.Strategy`.
    pool: `Pool`.
    config: planning config.
    seed: int.
    trainer: `Trainer` (models, caches).
    budgets: {purpose: RenderSettings} shared across strategies; updated in place.
    on_round: optional callback(round_index, selected list) after every added view.

  Returns:
    list of `Selected`, the initial view first.
  """
  if strategy.new_poses and pool.oracle is None:
    raise ValueError(f"strategy {strategy.name} proposes new poses; the pool "
                     f"{pool.name!r} has no oracle to capture them")
  cands = pool.candidates
  first = initial_index(config, seed, len(cands))
  selected = [candidate_view(pool, first)]
  available = np.ones(len(cands), bool)
  available[first] = False
  while len(selected) < int(config.max_views):
    t0 = time.perf_counter()
    choice = choose_next(strategy, pool, config, seed, trainer, budgets, selected, available)
    if choice.index is not None:
      image = np.asarray(cands.images[choice.index])
      available[choice.index] = False
    else:
      image = np.asarray(pool.oracle(choice.camera))
    info = {}
    if "uv0" in choice.info:
      info = {"uv0": choice.info["uv0"].tolist(), "uv": choice.info["uv"].tolist(),
              "start_index": choice.info.get("start_index"),
              "u_start": choice.info["u_start"], "u_end": choice.info["u_end"]}
      if "kept_step" in choice.info:  # Ours (Opt. Best): which pose it kept, and their U.
        info.update(kept_step=choice.info["kept_step"],
                    start_score=choice.info["start_score"],
                    visited_steps=choice.info["visited_steps"].tolist(),
                    u_visited=choice.info["u_visited"].tolist())
    selected.append(Selected(choice.index, choice.camera, image, choice.score,
                             time.perf_counter() - t0, info))
    if on_round is not None:
      on_round(len(selected) - 1, selected)
  return selected


def run_record(strategy, seed, selected, metrics, seconds, pool):
  """The json-able record of one (strategy, seed) run."""
  uv = poses.camera_to_uv(stack_cameras([s.camera for s in selected]), pool.sphere.center)
  return {
      "strategy": strategy.name, "label": strategy.label, "seed": int(seed),
      "indices": [None if s.index is None else int(s.index) for s in selected],
      "world_to_camera": [np.asarray(s.camera.world_to_camera).tolist() for s in selected],
      "uv": uv.tolist(), "scores": [float(s.score) for s in selected],
      "round_seconds": [float(s.seconds) for s in selected],
      "optimisation": [s.info for s in selected],
      "metrics": {str(n): m for n, m in metrics.items()}, "seconds": float(seconds),
  }


def selected_from_record(record, pool):
  """The views of a run record (`run_record`) as `Selected`, to train on them again.

  Candidates come from the pool; new poses (the optimising strategies) are captured again
  by the pool's oracle. Scores, timings and extras are not restored.
  """
  from mfsample.camera import Camera

  cands = pool.candidates
  out = []
  for index, w2c in zip(record["indices"], record["world_to_camera"], strict=True):
    if index is not None:
      out.append(candidate_view(pool, index))
      continue
    if pool.oracle is None:
      raise ValueError(f"{record['strategy']} chose a new pose but the pool has no oracle.")
    ref = cands.cameras[0]
    camera = Camera.create(np.asarray(w2c, np.float32), ref.fx, ref.fy, ref.cx, ref.cy,
                           ref.width, ref.height)
    out.append(Selected(None, camera, np.asarray(pool.oracle(camera)), float("nan"), 0.0, {}))
  return out


# ------------------------------------------------------------------ the loop


def run_camera_planning(config, workdir):
  """Runs the protocol for every seed and strategy of `config`; writes and returns results.

  Writes to `workdir`: `runs/<strategy>-seed<seed>.json` (as each finishes; existing ones
  are loaded, not recomputed), `results.json`, `table.md`, `cameras.png`, `landscape.png`
  (+ `landscape.npz`) and `config.json`, each atomically. An invalid config
  (`mfsample.planning.config.validate`) and a workdir whose finished runs used another
  protocol (`workdirs.check_resumable`) are refused before anything is written.

  Returns:
    the results dict (as in `results.json`).
  """
  from tqdm.auto import tqdm

  t_start = time.perf_counter()
  validate(config)
  workdirs.check_resumable(config, workdir)
  pool = make_pool(config.data)
  if int(config.max_views) > len(pool.candidates):
    raise ValueError(f"config.max_views = {config.max_views}: the pool has only "
                     f"{len(pool.candidates)} candidates")
  initial_index(config, 0, len(pool.candidates))  # refuses an initial_view beyond the pool
  os.makedirs(os.path.join(workdir, "runs"), exist_ok=True)
  workdir_lib.write_config(config, workdir)
  names = list(config.strategies)
  skipped = []
  if pool.oracle is None:
    skipped = [n for n in names if strategies.make_strategy(n, config).new_poses]
    names = [n for n in names if n not in skipped]
  # Each (seed, strategy) once, even if a caller skipped `validate`.
  todo = list(dict.fromkeys((int(seed), name) for seed in config.seeds for name in names))
  eval_views = tuple(int(n) for n in config.eval_views)
  rounds = int(config.max_views) - 1
  lpips_fn = None
  if config.eval.lpips_net:
    lpips_fn = metrics_lib.make_lpips(config.eval.lpips_net)
  trainer = Trainer(config, pool)
  budgets = {}
  records = []
  bar = tqdm(total=len(todo) * (rounds + len(eval_views)), desc="camera planning",
             disable=not config.progress, dynamic_ncols=True)
  for seed, name in todo:
    path = os.path.join(workdir, "runs", f"{workdirs.run_name(name, seed)}.json")
    if os.path.exists(path):
      with open(path) as f:
        records.append(json.load(f))
      bar.update(rounds + len(eval_views))
      continue
    strategy = record_rounds(strategies.make_strategy(name, config), workdir, config, seed)
    bar.set_postfix_str(f"{strategy.label}, seed {seed}")
    t_run = time.perf_counter()
    selected = plan_views(strategy, pool, config, seed, trainer, budgets,
                          on_round=lambda *_: bar.update(1))
    metrics = {}
    for n in eval_views:
      model = trainer.final_model(selected[:n], seed)
      metrics[n], budgets["eval"] = evaluate_model(
          model, pool.test, background=pool.background, lpips_fn=lpips_fn,
          settings=budgets.get("eval") or trainer.settings.get("final"))
      bar.update(1)
    record = run_record(strategy, seed, selected, metrics, time.perf_counter() - t_run, pool)
    write_json(path, record, indent=1)
    records.append(record)
  bar.close()

  summary = tables.summarise(records, eval_views)
  labels = {rec["strategy"]: rec["label"] for rec in records}
  paired = {}
  if len(config.seeds) > 1:
    paired = {ref: tables.paired_differences(records, eval_views, ref)
              for ref in config.paired_references if ref in labels}
  optimisation = tables.optimisation_summary(records)
  run_seconds = tables.seconds_summary(records)
  title = (f"Active camera planning on `{pool.name}`: {len(config.seeds)} seed(s), "
           f"mean ± std over seeds.")
  write_text(os.path.join(workdir, "table.md"),
             tables.report_markdown(summary, paired, optimisation, run_seconds, labels,
                                    eval_views, title))
  if config.figures.enabled:
    figures.camera_figure(records, pool, os.path.join(workdir, "cameras.png"),
                          seed=int(config.seeds[0]))
    land = landscape(config, pool, trainer, budgets)
    with atomic_path(os.path.join(workdir, "landscape.npz")) as tmp:
      np.savez(tmp, **land)
    figures.landscape_figure(land, os.path.join(workdir, "landscape.png"))
  results = {
      **workdirs.pool_record(pool), "seeds": list(config.seeds), "strategies": names,
      "skipped_strategies": skipped, "eval_views": list(eval_views),
      "round_steps": int(config.rounds.steps), "warm_start": bool(config.rounds.warm_start),
      "final_steps": int(config.final_train.train.num_steps),
      "summary": summary, "paired_psnr": paired, "optimisation": optimisation,
      "run_seconds": run_seconds, "runs": records,
      "seconds_this_call": time.perf_counter() - t_start,
  }
  write_json(os.path.join(workdir, "results.json"), results, indent=1)
  return results


def landscape(config, pool: Pool, trainer: Trainer, budgets):
  """U over a latitude-longitude grid of cameras (paper Fig. 7) for the 1-view model.

  The model is the first round's stochastic model of the first seed (one training view);
  an optimisation from a random start (Ours (Opt. Rnd.)'s first step) is traced on top.

  Returns:
    dict of arrays: values [nv, nu], u [nu], v [nv], train_uv [1, 2], and (when enabled)
    trajectory [steps + 1, 2].
  """
  seed = int(config.seeds[0])
  cands = pool.candidates
  first = initial_index(config, seed, len(cands))
  sel = [candidate_view(pool, first)]
  model = trainer.round_model("stochastic", sel, seed)
  f = config.figures
  down = int(config.strategy.optimize.downscale)
  sphere = pool.sphere.replace(width=max(pool.sphere.width // down, 1),
                               height=max(pool.sphere.height // down, 1))
  grid, u, v = poses.uv_grid(sphere, int(f.landscape_u), int(f.landscape_v))
  cams = poses.spherical_camera(jnp.asarray(grid.reshape(-1, 2)), sphere)
  z = unc.uncertainty_z(model, int(config.strategy.ours.select_samples),
                        int(config.strategy.ours.z_seed))
  scores, budgets["landscape"] = unc.score_cameras(
      model, cams, z, settings=budgets.get("landscape") or budgets.get("score")
      or trainer.settings.get(("round", "stochastic")),
      background=jnp.asarray(pool.background))
  out = {"values": np.asarray(scores.values).reshape(grid.shape[:2]), "u": u, "v": v,
         "train_uv": poses.camera_to_uv(sel[0].camera, pool.sphere.center)[None],
         "candidates_uv": poses.camera_to_uv(cands.cameras, pool.sphere.center)}
  if f.landscape_trajectory and pool.oracle is not None:
    strategy = strategies.make_strategy("ours_opt_rnd", config)
    inputs = strategies.Inputs(model, stack_cameras([sel[0].camera]), cands.cameras,
                               np.ones(len(cands), bool), pool.sphere, pool.bounds,
                               pool.background, {"start": scoring_start(config), **budgets})
    key = jax.random.fold_in(jax.random.PRNGKey(seed), 1234)
    choice = strategy.select(inputs, key)
    out["trajectory"] = choice.info["trajectory"]
    out["trajectory_values"] = choice.info["values"]
  return out
