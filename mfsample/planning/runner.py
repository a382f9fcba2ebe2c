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
import dataclasses
import hashlib
import os
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import interrupts, jobs
from mfsample import metrics as metrics_lib
from mfsample import view_uncertainty as unc
from mfsample.baselines import activenerf
from mfsample.config_blocks import data_spec, speed_only_fields
from mfsample.data import FILE_KINDS
from mfsample.data._io import area_downscale
from mfsample.data.views import Views
from mfsample.jobs import Budgets
from mfsample.planning import figures, poses, strategies, tables, training
from mfsample.planning import rounds as rounds_lib
from mfsample.planning.config import check_image_size, strategy_settings, validate
from mfsample.planning.pool import Pool, make_pool, stack_cameras
from mfsample.samplers import STOCHASTIC_KINDS, sample_z
from mfsample.train.config import recipe
from mfsample.train.evaluate import mean_metrics
from mfsample.train.step import clear_compiled_steps


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


def round_recipe(config, kind):
  """The `Recipe` of the round models of a kind.

  "stochastic" keeps the round config's sampler; "lowrank", "diagonal" or "block" replace
  it; "deterministic" and "variance" (ActiveNeRF's) are plain 3DGS.

  Re-initialised rounds (the authors' code) train `rounds.steps` steps each. With
  `rounds.warm_start` (the paper's text: one run, a camera added every so many steps) the
  schedules span the whole run: `rounds.first_steps` + (max_views - 2) * `rounds.steps`.
  """
  r = config.rounds
  base = recipe(config.round_train, prefix="config.round_train")
  spec = base.spec
  if kind in ("deterministic", "variance"):
    spec = dataclasses.replace(spec, kind="deterministic")
  elif kind in STOCHASTIC_KINDS:  # a strategy that names its sampler
    spec = dataclasses.replace(spec, kind=kind)
  steps = int(r.steps)
  if r.warm_start:
    steps = int(r.first_steps) + (int(config.max_views) - 2) * int(r.steps)
  return base._replace(spec=spec, settings=base.settings.replace(num_steps=steps))


def _round_budget(kind):
  return f"round_{kind}"


class Trainer:
  """Trains (and caches) models for the rounds and the final evaluation.

  Host-side memo only: the cache maps (kind, seed, view keys) to trained models. The render
  budgets that sufficed for each kind of model travel in the caller's `Budgets` (purposes
  "round_<kind>" and "final"): every method takes the record and returns the new one.
  """

  def __init__(self, config, pool: Pool, cache_size=24):
    self.config = config
    self.pool = pool
    self.strategy = strategy_settings(config)
    self.final = recipe(config.final_train, prefix="config.final_train")
    self.cache = collections.OrderedDict()
    self.cache_size = cache_size
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

  def _train(self, plan, selected, seed, render, downscale=1, state=None, stop_at=None):
    """Trains `plan` (a `Recipe`) on the `selected` views, its renders starting from
    `render` (None: the recipe's own budget).

    A fixed-shape model trains padded to `max_views` image slots (one compilation for every
    view count; `state` / `stop_at` continue one, see `training.train_on_views`); a model
    that densifies changes shape anyway and trains with `run_training` as it is.
    """
    views = as_views(selected, downscale)
    t0 = time.perf_counter()
    if plan.densifies():
      clear_compiled_steps()  # the earlier models' shapes would pile up (see there)
      trained = training.train_densified(plan, views, seed=seed, bounds=self.pool.bounds,
                                         render=render, points=self.pool.points)
    else:
      trained = training.train_on_views(plan, views, seed=seed, bounds=self.pool.bounds,
                                        pad_to=self.config.max_views, render=render,
                                        state=state, stop_at=stop_at, points=self.pool.points)
    self.train_seconds += time.perf_counter() - t0
    return trained

  def round_state(self, base, selected, seed, budgets: Budgets):
    """(`training.Trained` of a model of kind `base` after the round on `selected`
    (cached), budgets).

    Warm start: the previous round's state (recursively) continued for `rounds.steps` more
    steps on the larger view set; otherwise a fresh model trained `rounds.steps` steps,
    with densification where the round config asks for it (the authors' rounds).
    """
    keys = tuple(view_key(s) for s in selected)
    r = self.config.rounds
    plan = round_recipe(self.config, base)

    def make():
      nonlocal budgets
      state, stop_at = None, int(r.steps)
      if plan.densifies():
        if r.warm_start:
          raise ValueError("rounds.warm_start continues one padded state, which cannot "
                           "densify: set round_train.densify.start >= rounds.steps")
      elif r.warm_start:
        stop_at = int(r.first_steps)
        if len(selected) > 1:
          prev, budgets = self.round_state(base, selected[:-1], seed, budgets)
          state, stop_at = prev.state, int(prev.state.step) + int(r.steps)
      return self._train(plan, selected, seed, budgets.get(_round_budget(base)),
                         int(r.downscale), state, stop_at)

    trained = self._cached(("round", base, seed, keys), make)
    return trained, budgets.replace(**{_round_budget(base): trained.settings})

  def round_model(self, kind, selected, seed, budgets: Budgets):
    """(The model of `kind` for the round on the `selected` views (cached), budgets)."""
    base = "deterministic" if kind == "variance" else kind
    trained, budgets = self.round_state(base, selected, seed, budgets)
    if kind != "variance":
      return trained.model, budgets
    keys = tuple(view_key(s) for s in selected)

    def make():
      a = self.strategy.activenerf
      t0 = time.perf_counter()
      vmodel, _ = activenerf.fit_variance(
          trained.model, as_views(selected, int(self.config.rounds.downscale)),
          settings=trained.settings,
          background=self.pool.background, steps=a.steps, lr=a.lr,
          prior_var=a.prior_var, beta_min=a.beta_min,
          prior_weight=a.prior_weight, seed=seed, pad_to=self.config.max_views)
      self.train_seconds += time.perf_counter() - t0
      return vmodel

    return self._cached(("variance", seed, keys), make), budgets

  def final_model(self, selected, seed, budgets: Budgets):
    """(The plain model of the final evaluation, trained on `selected` (cached), budgets)."""
    keys = tuple(view_key(s) for s in selected)
    trained = self._cached(("final", seed, keys), lambda: self._train(
        self.final, selected, seed, budgets.get("final")))
    return trained.model, budgets.replace(final=trained.settings)


def scoring_start(config):
  """Starting settings of the strategies' renders (scores, ascents): the round models'
  renderer (`round_train.render`: footprint rule, compositor) with a small budget, grown
  on overflow."""
  return recipe(config.round_train, prefix="config.round_train").settings.render \
      .holding_budget(1 << 12)


def choose_next(strategy, pool: Pool, config, seed, trainer: Trainer, budgets: Budgets,
                selected, available):
  """One round of a strategy: its choice of the next view after the views `selected`.

  Trains (or takes from `trainer`'s cache) the round model the strategy needs and draws its
  random key from the seed, the strategy's stream and the round, so a round can be replayed
  alone.

  Args:
    strategy: `strategies.Strategy`.
    pool: `Pool`.
    config: planning config.
    seed: int.
    trainer: `Trainer`.
    budgets: `Budgets` that sufficed so far (shared by the strategies of a call).
    selected: list of `Selected`, the current views.
    available: [C] bool, candidates not selected yet.

  Returns:
    (the strategy's `strategies.Choice`, the `Budgets` to use next).
  """
  model = None
  if strategy.model_kind is not None:
    model, budgets = trainer.round_model(strategy.model_kind, selected, seed, budgets)
  inputs = strategies.Inputs(
      model=model, train_cameras=stack_cameras([s.camera for s in selected]),
      candidates=pool.candidates.cameras, available=available, sphere=pool.sphere,
      bounds=pool.bounds, background=pool.background,
      renders=strategies.Renders(budgets.get("score"), budgets.get("optimize")),
      start=scoring_start(config), max_views=int(config.max_views))
  choice = strategy.select(inputs, strategies.strategy_key(seed, strategy.name, len(selected)))
  return choice, budgets.replace(score=choice.renders.score, optimize=choice.renders.optimize)


def plan_views(strategy, pool: Pool, config, seed, trainer: Trainer, budgets=Budgets(),
               on_round=None):
  """Runs one strategy for one seed up to `config.max_views` views.

  Args:
    strategy: `strategies.Strategy`.
    pool: `Pool`.
    config: planning config.
    seed: int.
    trainer: `Trainer` (models, caches).
    budgets: `Budgets` to start from.
    on_round: optional callback(round_index, selected list) after every added view.

  Returns:
    (list of `Selected`, the initial view first; the `Budgets` that sufficed).
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
    interrupts.check(f"in round {len(selected)} of {strategy.name}, seed {seed}")
    t0 = time.perf_counter()
    choice, budgets = choose_next(strategy, pool, config, seed, trainer, budgets, selected,
                                  available)
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
  return selected, budgets


def export_views(directory, selected):
  """A run's views as files viewers and capture tools read (`data.camera_export`: nerfstudio
  transforms.json and camera_path.json, the 3DGS cameras.json, COLMAP text), with the image
  captured at each (`images/`), in the order they were chosen."""
  from mfsample.data.camera_export import export_cameras

  names = [f"{i:02d}_" + (f"candidate_{s.index}" if s.index is not None else "new_pose")
           for i, s in enumerate(selected)]
  return export_cameras(directory, stack_cameras([s.camera for s in selected]), names,
                        images=np.stack([s.image for s in selected]))


def run_name(strategy, seed):
  """A run's file name in `runs/` (without `.json`)."""
  return f"{strategy}-seed{seed}"


def pool_record(pool):
  """What results.json records of the pool: scene, [width, height], candidate and test counts."""
  return {"scene": pool.name,
          "resolution": [int(pool.candidates.images.shape[2]),
                         int(pool.candidates.images.shape[1])],
          "num_candidates": len(pool.candidates), "num_test": len(pool.test)}


def run_record(strategy, seed, selected, metrics, seconds, pool):
  """The json-able record of one (strategy, seed) run."""
  uv = poses.camera_to_uv(stack_cameras([s.camera for s in selected]), pool.sphere.center)
  return {
      "strategy": strategy.name, "label": strategy.label, "seed": int(seed),
      "indices": [None if s.index is None else int(s.index) for s in selected],
      "world_to_camera": [np.asarray(s.camera.world_to_camera).tolist() for s in selected],
      # The initial view has no score (nan): null in the record, as it reads back.
      "uv": uv.tolist(), "scores": [float(s.score) if np.isfinite(s.score) else None
                                    for s in selected],
      "round_seconds": [float(s.seconds) for s in selected],
      "optimisation": [s.info for s in selected],
      "metrics": {str(n): m for n, m in metrics.items()}, "seconds": float(seconds),
  }


# ------------------------------------------------------------------ the loop


def run_camera_planning(config, workdir):
  """Runs the protocol for every seed and strategy of `config`; writes and returns results.

  Writes to `workdir`: `runs/<strategy>-seed<seed>.json` (as each finishes; existing ones
  are loaded, not recomputed, and a damaged one is reported and recomputed) with its views
  in viewers' formats in `views/<strategy>-seed<seed>/` (`export_views`), `results.json`,
  `table.md`, `cameras.png`, `landscape.png` (+ `landscape.npz`) and `config.json`, each
  atomically. An invalid config (`mfsample.planning.config.validate`) and a workdir whose
  finished runs used another protocol are refused before anything is written (`JOB`).

  Returns:
    the results dict (as in `results.json`).
  """
  t_start = time.perf_counter()
  with jobs.open_workdir(JOB, config, workdir) as wd:
    wd.stage(f"loading the candidate pool ({config.data.kind} data)")
    pool = make_pool(data_spec(config.data))
    if int(config.max_views) > len(pool.candidates):
      raise ValueError(f"config.max_views = {config.max_views}: the pool has only "
                       f"{len(pool.candidates)} candidates")
    initial_index(config, 0, len(pool.candidates))  # refuses an initial_view beyond the pool
    _, height, width = np.shape(pool.candidates.images)[:3]
    check_image_size(config, width, height,
                     config.data.path if config.data.kind in FILE_KINDS else None)
    wd.write_config()
    settings = strategy_settings(config)
    names = list(config.strategies)
    skipped = []
    if pool.oracle is None:
      skipped = [n for n in names if strategies.make_strategy(n, settings).new_poses]
      names = [n for n in names if n not in skipped]
    # Each (seed, strategy) once, even if a caller skipped `validate`.
    todo = list(dict.fromkeys((int(seed), name) for seed in config.seeds for name in names))
    eval_views = tuple(int(n) for n in config.eval_views)
    rounds = int(config.max_views) - 1
    lpips_fn = None
    if config.eval.lpips_net:
      lpips_fn = metrics_lib.make_lpips(config.eval.lpips_net)
    trainer = Trainer(config, pool)
    budgets = Budgets()
    records = []
    wd.stage(f"{len(todo)} run(s) of {rounds} round(s) each, then the final models at "
             f"{', '.join(map(str, eval_views))} views (the first round compiles)")
    bar = wd.progress(len(todo) * (rounds + len(eval_views)))
    for seed, name in todo:
      entry = f"runs/{run_name(name, seed)}.json"
      record = wd.read_json(entry)
      if record is not None:
        records.append(record)
        bar.update(rounds + len(eval_views))
        continue
      strategy = strategies.make_strategy(name, settings)
      if wd.writes:  # the rounds the viewer shows, recorded by the writing process only
        strategy = rounds_lib.record_rounds(
            strategy, wd.file(rounds_lib.DIRECTORY), run_name(name, seed), seed,
            keep_models=seed == int(config.seeds[0]), keep=int(config.max_views))
      bar.set_postfix_str(f"{strategy.label}, seed {seed}")
      t_run = time.perf_counter()
      selected, budgets = plan_views(strategy, pool, config, seed, trainer, budgets,
                                     on_round=lambda *_: bar.update(1))
      metrics = {}
      for n in eval_views:
        model, budgets = trainer.final_model(selected[:n], seed, budgets)
        metrics[n], eval_settings = mean_metrics(
            model, pool.test, background=pool.background, lpips_fn=lpips_fn,
            settings=budgets.first("eval", "final"))
        budgets = budgets.replace(eval=eval_settings)
        bar.update(1)
      record = run_record(strategy, seed, selected, metrics, time.perf_counter() - t_run,
                          pool)
      if wd.writes:
        export_views(wd.file("views", run_name(name, seed)), selected)
      # After its views: marks the run done, while its views are what it wrote.
      wd.write_json(entry, record, files=(os.path.join("views", run_name(name, seed)),))
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
    wd.write_text("table.md", tables.report_markdown(summary, paired, optimisation,
                                                     run_seconds, labels, eval_views, title))
    if config.figures.enabled:
      wd.stage("figures: cameras.png, and U over the sphere of cameras (landscape.png)")
      if wd.writes:
        figures.camera_figure(records, pool, wd.file("cameras.png"), seed=int(config.seeds[0]))
      land, budgets = landscape(config, pool, trainer, budgets)  # (every process computes)
      wd.save_arrays("landscape.npz", **land)
      if wd.writes:
        figures.landscape_figure(land, wd.file("landscape.png"))
    results = {
        **pool_record(pool), "seeds": list(config.seeds), "strategies": names,
        "skipped_strategies": skipped, "eval_views": list(eval_views),
        "round_steps": int(config.rounds.steps), "warm_start": bool(config.rounds.warm_start),
        "final_steps": int(config.final_train.train.num_steps),
        "summary": summary, "paired_psnr": paired, "optimisation": optimisation,
        "run_seconds": run_seconds, "runs": records,
        "seconds_this_call": time.perf_counter() - t_start,
    }
    wd.write_json("results.json", results)
    return results


def landscape(config, pool: Pool, trainer: Trainer, budgets: Budgets):
  """U over a latitude-longitude grid of cameras (paper Fig. 7) for the 1-view model.

  The model is the first round's stochastic model of the first seed (one training view);
  an optimisation from a random start (Ours (Opt. Rnd.)'s first step) is traced on top.

  Returns:
    (dict of arrays: values [nv, nu], u [nu], v [nv], train_uv [1, 2], and (when enabled)
    trajectory [steps + 1, 2]; the `Budgets` that sufficed).
  """
  seed = int(config.seeds[0])
  cands = pool.candidates
  first = initial_index(config, seed, len(cands))
  sel = [candidate_view(pool, first)]
  model, budgets = trainer.round_model("stochastic", sel, seed, budgets)
  f = config.figures
  settings = trainer.strategy
  down = settings.optimize.downscale
  sphere = pool.sphere.replace(width=max(pool.sphere.width // down, 1),
                               height=max(pool.sphere.height // down, 1))
  grid, u, v = poses.uv_grid(sphere, int(f.landscape_u), int(f.landscape_v))
  cams = poses.spherical_camera(jnp.asarray(grid.reshape(-1, 2)), sphere)
  z = sample_z(model, settings.ours.select_samples, seed=settings.ours.z_seed)
  scores, grown = unc.score_cameras(
      model, cams, z, settings=budgets.first("landscape", "score", _round_budget("stochastic")),
      background=jnp.asarray(pool.background))
  budgets = budgets.replace(landscape=grown)
  out = {"values": np.asarray(scores.values).reshape(grid.shape[:2]), "u": u, "v": v,
         "train_uv": poses.camera_to_uv(sel[0].camera, pool.sphere.center)[None],
         "candidates_uv": poses.camera_to_uv(cands.cameras, pool.sphere.center)}
  if f.landscape_trajectory and pool.oracle is not None:
    strategy = strategies.make_strategy("ours_opt_rnd", settings)
    inputs = strategies.Inputs(model, stack_cameras([sel[0].camera]), cands.cameras,
                               np.ones(len(cands), bool), pool.sphere, pool.bounds,
                               pool.background,
                               strategies.Renders(budgets.get("score"), budgets.get("optimize")),
                               scoring_start(config))
    key = jax.random.fold_in(jax.random.PRNGKey(seed), LANDSCAPE_STREAM)
    choice = strategy.select(inputs, key)
    out["trajectory"] = choice.info["trajectory"]
    out["trajectory_values"] = choice.info["values"]
    budgets = budgets.replace(score=choice.renders.score, optimize=choice.renders.optimize)
  return out, budgets


# The random stream of the landscape's trajectory (apart from every strategy's).
LANDSCAPE_STREAM = 1234
# Fields a later call on the same workdir may change: which runs to do (seeds, strategies),
# presentation, and the training configs' speed-only fields.
FREE_FIELDS = ("seeds", "strategies", "progress", "figures", "data.progress",
               "paired_references") + speed_only_fields("round_train") + speed_only_fields(
                   "final_train")
JOB = jobs.Job("camera planning", "camera_planning", run_camera_planning, validate,
               FREE_FIELDS, ("runs",), report=jobs.table_report)
