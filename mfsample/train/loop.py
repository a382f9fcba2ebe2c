"""The host loop: `train` (reusable) and `train_and_evaluate` (the experiment entry point).

The loop is thin: it picks the view and Sobol rows of each step (both functions of
(seed, step)), calls the jitted step, grows the render budget when a step reports
overflow (the step left the state untouched, so it is simply re-run), and runs the host
events of 3DGS (densification, opacity reset) and checkpoints between steps.

Resuming is safe: a workdir (`train_and_evaluate`) or checkpoint directory (`train`) made
with a different config is refused, naming the fields that differ; a checkpoint that
cannot be read is reported by path and the newest intact one is used instead.
"""

import dataclasses
import os
import time
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import workdir as workdir_lib
from mfsample._json import without_fields, write_json
from mfsample.data import datasets as data_lib
from mfsample.model import GROUPS, SamplerSpec, group_shapes
from mfsample.renderer.budget import BudgetExceededError, fit_budget
from mfsample.renderer.settings import RenderSettings
from mfsample.samplers import sobol_z
from mfsample.train import checkpoint as ckpt
from mfsample.train import densify as densify_lib
from mfsample.train import initial, optim
from mfsample.train.config import validate
from mfsample.train.step import StepConfig, TrainState, init_train_state, make_train_step


class TrainSetup(NamedTuple):
  """Host-side constants of a run, derived from the config and the training views."""

  seed: int  # seeds the initial cloud, B_hat signs, step keys, view order, densification
  extent: float  # scene extent (world units)
  spec: SamplerSpec
  init_scales: dict  # {group: float} scale of fresh B_hat entries
  step_config: StepConfig  # static settings of the jitted step (budget included)
  num_steps: int
  sobol: np.ndarray  # [num_steps * M, k] z rows (empty unless lowrank + Sobol)


class TrainResult(NamedTuple):
  """What `train` returns."""

  state: TrainState
  setup: TrainSetup  # with the render budget that sufficed
  # Dicts logged every `config.train.log_every` steps, from step 0: a resumed run carries
  # the log of the checkpoint it started from, so nothing is lost or logged twice.
  history: list
  seconds: float  # wall-clock of the steps run in this call (compilation included)
  train_seconds: float  # wall-clock of all the steps, summed over resumed segments


# ------------------------------------------------------------------------- setup


def sampler_spec(config, extent, sh_degree):
  """`SamplerSpec` from `config.sampler` (bounds of the centres scale with the extent)."""
  groups = tuple(g for g in config.sampler.groups if g in group_shapes(sh_degree))
  bounds = tuple((g, float(config.sampler.bounds[g]) * (extent if g == "means" else 1.0))
                 for g in groups)
  return SamplerSpec(kind=config.sampler.kind, rank=int(config.sampler.rank), groups=groups,
                     bounds=bounds)


# Training-config fields that change only how fast a run goes, never what it computes
# (beyond float rounding): a resumed run or a reused result may differ in them.
SPEED_ONLY_FIELDS = ("render.chunks_per_step", "render.compositor")


def without_speed_only_fields(train_config_dict):
  """A training config as a JSON dict, less `SPEED_ONLY_FIELDS`: what results depend on."""
  return without_fields(train_config_dict, SPEED_ONLY_FIELDS)


# Fields a resumed run may change: the speed-only ones, the progress bar, and which
# checkpoints are written and kept (a restored state is bit-identical whichever it is).
RESUME_FREE_FIELDS = SPEED_ONLY_FIELDS + ("train.progress", "train.checkpoint_every",
                                          "train.keep_checkpoints")


def resumable_config(config):
  """A training config as a JSON dict, less `RESUME_FREE_FIELDS` (what checkpoints record)."""
  return without_fields(workdir_lib.config_dict(config), RESUME_FREE_FIELDS)


def render_settings(render_config):
  """`RenderSettings` of a training config's `render` block.

  The initial budget is rounded up to a whole number of compositing steps
  (chunk_size x chunks_per_step), so any `chunks_per_step` is valid with any start.
  """
  chunks_per_step = int(render_config.get("chunks_per_step", RenderSettings.chunks_per_step))
  return RenderSettings.holding(
      render_config.max_intersections, tile_size=int(render_config.tile_size),
      chunks_per_step=chunks_per_step,
      radius_sigma=float(render_config.get("radius_sigma", RenderSettings.radius_sigma)),
      compositor=str(render_config.get("compositor", RenderSettings.compositor)))


def make_setup(config, train_views, *, extent=None, key=None):
  """`TrainSetup` for training on `train_views` with `config`.

  Args:
    config: training config.
    train_views: `Views` (their cameras give the scene extent).
    extent: overrides `config.data.extent` and the cameras' extent.
    key: optional PRNG key; replaces `config.seed` as the source of all randomness
      (the Sobol scrambling keeps `config.sampler.z_seed`).
  """
  seed = int(config.seed) if key is None else int(
      jax.random.randint(key, (), 0, np.iinfo(np.int32).max))
  if extent is None:
    extent = (config.data.extent if config.data.get("extent") is not None
              else data_lib.scene_extent(train_views.cameras))
  sh_degree = int(config.model.sh_degree)
  spec = sampler_spec(config, extent, sh_degree)
  init_scales = {g: config.sampler.init_scale * (extent if g in config.sampler.init_extent_groups
                                                 else 1.0) for g in GROUPS}
  num_steps = int(config.train.num_steps)
  max_steps = config.optim.position_lr_max_steps or num_steps
  rates = optim.learning_rates(config.optim, config.sampler.lr, extent, max_steps)
  volume_weight = config.loss.volume_weight
  if volume_weight is None:
    volume_weight = 1.0 / len(train_views)
  settings = render_settings(config.render)
  step_config = StepConfig(
      settings=settings,
      background=tuple(float(c) for c in config.data.background),
      num_samples=int(config.sampler.num_samples),
      ssim_weight=float(config.loss.ssim_weight),
      volume_weight=float(volume_weight),
      volume_every=int(config.loss.volume_every),
      volume_until=num_steps - int(config.loss.volume_stop_before_end),
      stats_until=int(config.densify.stop),
      sh_degree_every=int(config.densify.sh_degree_every),
      stochastic_until=(2**31 - 1 if config.sampler.stochastic_until is None
                        else int(config.sampler.stochastic_until)),
      rates=rates,
  )
  m = step_config.num_samples
  if spec.kind == "lowrank" and spec.stochastic and config.sampler.z == "sobol":
    sobol = sobol_z(num_steps * m, spec.rank, int(config.sampler.z_seed))
  elif config.sampler.z not in ("sobol", "uniform"):
    raise ValueError(f"config.sampler.z must be 'sobol' or 'uniform', got {config.sampler.z!r}")
  else:
    sobol = np.zeros((num_steps * m, 0), np.float32)
  return TrainSetup(seed=seed, extent=float(extent), spec=spec, init_scales=init_scales,
                    step_config=step_config,
                    num_steps=num_steps, sobol=sobol)


def init_state(config, setup: TrainSetup, bounds, points=None):
  """The step-0 `TrainState` of `config.model.init_from` (`mfsample.train.initial`): random
  points in the box `bounds` = (low [3], high [3]), the dataset's SfM `points` (a
  `PointCloud`), or a trained model's .ply."""
  key = jax.random.PRNGKey(setup.seed)
  k_model, k_train = jax.random.split(key)
  model = initial.initial_model(config, setup, bounds, points, k_model)
  return init_train_state(model, setup.step_config, k_train)


def view_for_step(seed, step, num_views):
  """The training view of `step`: epochs of random permutations (3DGS), seeded per epoch."""
  epoch, within = divmod(int(step), num_views)
  return int(np.random.default_rng([int(seed), 1, epoch]).permutation(num_views)[within])


# ------------------------------------------------------------------------- training


def _meta(config, setup, state, history, train_seconds):
  return {"step": int(state.step), "capacity": int(state.model.capacity),
          "max_intersections": int(setup.step_config.settings.max_intersections),
          "seed": setup.seed, "sobol_seed": int(config.sampler.z_seed),
          "sobol_position": int(state.step) * setup.step_config.num_samples,
          "extent": setup.extent, "history": history, "train_seconds": train_seconds,
          "config": resumable_config(config)}


def restore_latest(config, setup, bounds, directory, points=None):
  """(state, setup, meta) from the newest intact checkpoint in `directory`, or None if none.

  `meta` holds the training log up to that step ("history") and the wall-clock spent
  reaching it ("train_seconds"). An unreadable checkpoint (truncated, overwritten) is
  reported with a warning naming it, and the next older one is tried; a later save replaces
  it.

  Raises:
    mfsample.workdir.WorkdirError: the checkpoints were written by a run with another config
      or seed (the message names the fields).
    ckpt.CorruptCheckpointError: checkpoints exist but none can be read.
  """
  paths = ckpt.list_checkpoints(directory)
  if not paths:
    return None
  unreadable = []
  for path in reversed(paths):
    try:
      meta = ckpt.read_meta(path)
      _check_checkpoint_config(config, setup, meta, path)
      template = init_state(config, setup, bounds, points)
      template = densify_lib.grow_capacity(template, meta["capacity"])
      state, meta = ckpt.restore_checkpoint(path, template)
    except ckpt.CorruptCheckpointError as e:
      warnings.warn(f"{e}; trying an older checkpoint", stacklevel=2)
      unreadable.append(str(e))
      continue
    # Rounded: the checkpoint's run may have composited more or fewer chunks per step.
    settings = setup.step_config.settings.holding_budget(meta["max_intersections"])
    setup = setup._replace(step_config=dataclasses.replace(setup.step_config,
                                                           settings=settings))
    return state, setup, meta
  raise ckpt.CorruptCheckpointError(
      f"no readable checkpoint in {directory}: {'; '.join(unreadable)}. Remove them to "
      "train from scratch.")


def _check_checkpoint_config(config, setup, meta, path):
  """Refuses a checkpoint written with another seed or (where recorded) another config."""
  if meta.get("seed") != setup.seed:
    raise workdir_lib.WorkdirError(
        f"{path} was written by a run with seed {meta.get('seed')}, this run has seed "
        f"{setup.seed}: use another checkpoint directory")
  if "config" in meta:
    new = resumable_config(config)
    if meta["config"] != new:
      raise workdir_lib.WorkdirError(
          f"{path} was written by a run with a different config (differences: "
          f"{', '.join(workdir_lib.differences(meta['config'], new))}): use another "
          "checkpoint directory")


def with_grown_budget(setup, metrics, max_budget, step):
  """`setup` whose step renders with a budget that holds the overflowing step's intersections.

  Works for any setup NamedTuple with a `step_config` (colour and relightable training).

  Raises:
    BudgetExceededError: the step needs more than `max_budget` (config.render.max_budget).
  """
  settings = fit_budget(setup.step_config.settings, metrics)
  if settings.max_intersections > max_budget:
    raise BudgetExceededError(
        f"step {step} needs {int(metrics.num_padded)} intersections, more than "
        f"config.render.max_budget={max_budget}")
  return setup._replace(step_config=dataclasses.replace(setup.step_config, settings=settings))


def _host_events(config, setup, state, step):
  """Densification and opacity reset after `step` completed steps (3DGS schedule)."""
  d = config.densify
  report = None
  if d.start < step < d.stop and step % d.every == 0:
    state, report = densify_lib.densify_and_prune(
        state, rng=np.random.default_rng([setup.seed, 2, step]),
        grad_threshold=d.grad_threshold, percent_dense=d.percent_dense, extent=setup.extent,
        min_opacity=d.min_opacity, init_scales=setup.init_scales,
        max_gaussians=config.model.max_gaussians, prune_big=step > d.prune_big_after,
        max_screen_size=d.max_screen_size, max_world_size=d.max_world_size)
  white = all(c == 1.0 for c in setup.step_config.background)
  if step < d.stop and (step % d.opacity_reset_every == 0 or (white and step == d.start)):
    state = densify_lib.reset_opacity(state)
  return state, report


def train(config, views, key=None, *, setup=None, state=None, bounds=None,
          checkpoint_dir=None, stop_at=None, max_traces=None, num_views=None, points=None):
  """Trains a stochastic Gaussian field on `views` (reusable: planning calls this).

  Everything random is a function of the seed (`key` if given, else `config.seed`) and
  the step, so equal inputs give bit-identical results, and a resumed run continues
  exactly where a killed one stopped.

  Args:
    config: a training config (`default_config()`); `config.train.num_steps`
      sets the length.
    views: training `Views`.
    key: optional PRNG key replacing `config.seed`.
    setup: optional `TrainSetup` (default: `make_setup(config, views, key=key)`).
    state: optional starting `TrainState` (default: a fresh one, or the newest checkpoint
      in `checkpoint_dir`).
    bounds: (low [3], high [3]) of the initial point cloud (default: `config.data.init_bounds`).
    checkpoint_dir: if set, resume from and write checkpoints there.
    stop_at: stop after this many steps without a final checkpoint, as a killed run
      would (tests use it).
    max_traces: passed to `make_train_step` (tests: 1).
    num_views: draw the step's view among the first `num_views` of `views` only (default:
      all). Callers that pad `views` to a fixed count keep one compilation of the step
      while the number of real views grows (planning rounds).
    points: the dataset's SfM `PointCloud`, for `config.model.init_from = "points"`.

  Returns:
    `TrainResult`.
  """
  from tqdm.auto import tqdm

  validate(config)
  setup = setup or make_setup(config, views, key=key)
  if bounds is None:
    lo, hi = config.data.init_bounds
    bounds = (np.full(3, lo), np.full(3, hi))
  history, seconds_before = [], 0.0
  if state is None and checkpoint_dir:
    restored = restore_latest(config, setup, bounds, checkpoint_dir, points)
    if restored is not None:
      state, setup, meta = restored
      history = list(meta.get("history", []))
      seconds_before = float(meta.get("train_seconds", 0.0))
  if state is None:
    state = init_state(config, setup, bounds, points)
  views = data_lib.to_device(views)
  m = setup.step_config.num_samples
  step_fn = make_train_step(setup.step_config, max_traces)
  step = int(state.step)
  end = setup.num_steps if stop_at is None else min(stop_at, setup.num_steps)
  num_views = len(views) if num_views is None else int(num_views)
  bar = tqdm(total=setup.num_steps, initial=step, disable=not config.train.progress,
             desc=f"train {setup.spec.kind}", dynamic_ncols=True)
  t0 = time.perf_counter()
  while step < end:
    view = jnp.int32(view_for_step(setup.seed, step, num_views))
    rows = setup.sobol[step * m:(step + 1) * m]
    new_state, metrics = step_fn(state, views.images, views.cameras, view, rows)
    if bool(metrics.overflow):  # nothing was updated: grow the budget and redo the step
      setup = with_grown_budget(setup, metrics, int(config.render.max_budget), step)
      step_fn = make_train_step(setup.step_config, max_traces)
      continue
    state, step = new_state, step + 1
    state, report = _host_events(config, setup, state, step)
    if step % config.train.log_every == 0 or step == end:
      entry = {"step": step, "loss": float(metrics.loss), "data_loss": float(metrics.data_loss),
               "volume": float(metrics.volume), "live": state.model.num_live,
               "capacity": state.model.capacity,
               "budget": setup.step_config.settings.max_intersections,
               "seconds": seconds_before + time.perf_counter() - t0}
      if report is not None:
        entry["densify"] = report._asdict()
      history.append(entry)
      bar.set_postfix(loss=f"{entry['data_loss']:.4f}", n=entry["live"])
    bar.update(1)
    if checkpoint_dir and (step % config.train.checkpoint_every == 0
                           or (step == setup.num_steps)):
      meta = _meta(config, setup, state, history, seconds_before + time.perf_counter() - t0)
      ckpt.save_checkpoint(checkpoint_dir, state, meta, keep=config.train.keep_checkpoints)
  bar.close()
  seconds = time.perf_counter() - t0
  return TrainResult(state, setup, history, seconds, seconds_before + seconds)


# ------------------------------------------------------------------------- experiment


def check_workdir(config, workdir):
  """Refuses `workdir` when it holds checkpoints or results of another training config.

  Fields in `RESUME_FREE_FIELDS` may differ. A stale `config.json` with nothing computed
  from it is simply replaced.

  Raises:
    mfsample.workdir.WorkdirError: naming the differing fields.
  """
  has_results = bool(ckpt.list_checkpoints(os.path.join(workdir, "checkpoints"))) or any(
      os.path.exists(os.path.join(workdir, name)) for name in ("metrics.json",
                                                               "train_log.json"))
  workdir_lib.check_same_config(
      config, workdir, free_fields=RESUME_FREE_FIELDS, has_results=has_results,
      results="checkpoints or results",
      remedy="use a new --workdir, or the config that made them")


def train_and_evaluate(config, workdir):
  """Loads the data, trains (resuming from `workdir`), evaluates, writes everything.

  Writes to `workdir`: `checkpoints/`, `config.json`, `train_log.json`, `metrics.json`
  (test PSNR / SSIM / LPIPS of the mean model, iterations, wall-clock), `images/`
  (renders, ground truth, uncertainty maps of test views) and `point_cloud.ply`, each
  atomically. Nothing is written before the config is validated
  (`mfsample.train.config.validate`), the workdir is known to hold no results of another
  config (`check_workdir`) and the data are loaded.

  Returns:
    the final `TrainState`.
  """
  from mfsample import metrics
  from mfsample.data import ply as export_ply
  from mfsample.train import evaluate as eval_lib

  validate(config)
  check_workdir(config, workdir)
  dataset = data_lib.load_dataset(config.data)
  workdir_lib.write_config(config, workdir)
  result = train(config, dataset.train, bounds=dataset.bounds,
                 checkpoint_dir=os.path.join(workdir, "checkpoints"), points=dataset.points)
  state, setup = result.state, result.setup
  write_json(os.path.join(workdir, "train_log.json"), result.history)

  lpips_fn = metrics.make_lpips(config.eval.lpips_net) if config.eval.lpips_net else None
  model = state.model
  z = None
  if model.spec.stochastic and config.eval.uncertainty_samples > 0:
    from mfsample import samplers
    m = int(config.eval.uncertainty_samples)
    key = jax.random.PRNGKey(setup.seed + 3)
    rows = sobol_z(m, model.spec.rank, int(config.sampler.z_seed) + 1) \
        if model.spec.kind == "lowrank" else None
    z = samplers.draw_z(model, m, key, rows)
  t0 = time.perf_counter()
  ev = eval_lib.evaluate(model, dataset.test, background=dataset.background,
                         settings=setup.step_config.settings, lpips_fn=lpips_fn,
                         uncertainty_z=z)
  eval_seconds = time.perf_counter() - t0
  eval_lib.save_images(os.path.join(workdir, "images"), ev, dataset.test,
                       num=config.eval.save_images)
  if config.eval.export_ply:
    export_ply.export_ply(os.path.join(workdir, "point_cloud.ply"), model)  # atomic
  summary = dict(ev.metrics)
  summary.update({
      "sampler": model.spec.kind, "rank": model.spec.rank,
      "steps": int(state.step), "live_gaussians": model.num_live,
      "train_seconds": result.train_seconds, "eval_seconds": eval_seconds,
      "resolution": [int(dataset.train.images.shape[2]), int(dataset.train.images.shape[1])],
      "num_train_views": len(dataset.train), "per_view": ev.per_view,
  })
  write_json(os.path.join(workdir, "metrics.json"), summary)
  return state
