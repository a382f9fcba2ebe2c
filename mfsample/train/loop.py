"""The host loop: `run_steps` (every field) and `train` (reusable).

The loop is thin: it picks the target of each step (a function of (seed, step); with a
batch of B targets per step, the targets at positions tB .. tB + B - 1 of the same order),
calls the jitted step, grows the render budget when a step reports overflow (the step left the state
untouched, so it is simply re-run), and runs the host events of 3DGS (densification, opacity
reset) between steps (`run_steps`, shared by the colour and the relightable field). `train`
adds the log, the progress bar and checkpoints.

Resuming is safe: a checkpoint directory made with a different config is refused, naming
the fields that differ; a checkpoint that cannot be read is reported by path and the newest
intact one is used instead (`restore_latest`, for every field).
"""

import dataclasses
import time
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import distributed, interrupts, sharding
from mfsample import workdir as workdir_lib
from mfsample._json import without_fields
from mfsample.data import datasets as data_lib
from mfsample.model import GROUPS, SamplerSpec, group_shapes
from mfsample.renderer.budget import BudgetExceededError, fit_budget
from mfsample.samplers import sobol_z
from mfsample.train import checkpoint as ckpt
from mfsample.train import densify as densify_lib
from mfsample.train import initial, optim
from mfsample.train.config import SPEED_ONLY_FIELDS, render_settings, validate
from mfsample.train.step import (
    COLOUR,
    StepConfig,
    StepMetrics,
    TrainState,
    init_train_state,
    make_train_step,
)


class TrainSetup(NamedTuple):
  """Host-side constants of a run, derived from the config and the training views."""

  seed: int  # seeds the initial cloud, B_hat signs, step keys, view order, densification
  extent: float  # scene extent (world units)
  spec: SamplerSpec
  init_scales: dict  # {group: float} scale of fresh B_hat entries
  step_config: StepConfig  # static settings of the jitted step (budget included)
  num_steps: int  # steps of the whole run (the schedules span them)
  sobol: np.ndarray  # [num_steps * B * M, k] z rows (empty unless lowrank + Sobol)
  field: object = COLOUR  # the step's `Field` (static): colour, or relightable


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


def sampler_spec(sampler_config, extent, shapes):
  """`SamplerSpec` of a config's `sampler` block for a model with parameter groups `shapes`
  ({group: shape}); the bounds of the centres scale with the extent."""
  groups = tuple(g for g in sampler_config.groups if g in shapes)
  bounds = tuple((g, float(sampler_config.bounds[g]) * (extent if g == "means" else 1.0))
                 for g in groups)
  return SamplerSpec(kind=sampler_config.kind, rank=int(sampler_config.rank), groups=groups,
                     bounds=bounds)


def init_scales(sampler_config, extent, groups):
  """{group: scale of fresh B_hat entries}: `init_scale`, times the extent for the groups of
  `init_extent_groups`."""
  s = sampler_config
  return {g: float(s.init_scale) * (extent if g in s.init_extent_groups else 1.0)
          for g in groups}


def sobol_rows(spec, count, seed, source="sobol"):
  """[count, k] scrambled Sobol z rows of the steps (`source` "sobol", low-rank B_hat), or an
  empty [count, 0] (the step then draws uniform z from its key)."""
  if spec.kind == "lowrank" and spec.stochastic and source == "sobol":
    return sobol_z(int(count), spec.rank, int(seed))
  return np.zeros((int(count), 0), np.float32)


# Fields a resumed run may change: the speed-only ones, the progress bar, and which
# checkpoints are written and kept (a restored state is bit-identical whichever it is).
RESUME_FREE_FIELDS = SPEED_ONLY_FIELDS + ("train.progress", "train.checkpoint_every",
                                          "train.keep_checkpoints")


def resumable_config(config):
  """A training config as a JSON dict, less `RESUME_FREE_FIELDS` (what checkpoints record)."""
  return without_fields(workdir_lib.config_dict(config), RESUME_FREE_FIELDS)


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
  spec = sampler_spec(config.sampler, extent, group_shapes(int(config.model.sh_degree)))
  num_steps = int(config.train.num_steps)
  max_steps = config.optim.position_lr_max_steps or num_steps
  rates = optim.learning_rates(config.optim, config.sampler.lr, extent, max_steps)
  volume_weight = config.loss.volume_weight
  if volume_weight is None:
    volume_weight = 1.0 / len(train_views)
  batch_size = int(config.train.batch_size)
  step_config = StepConfig(
      settings=render_settings(config.render),
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
      batch_size=batch_size,
      # B = 1 runs the single-target step on one device (in every process alike).
      num_devices=1 if batch_size == 1 else sharding.default_num_devices(batch_size),
  )
  if config.sampler.z not in ("sobol", "uniform"):
    raise ValueError(f"config.sampler.z must be 'sobol' or 'uniform', got {config.sampler.z!r}")
  sobol = sobol_rows(spec, num_steps * batch_size * step_config.num_samples,
                     config.sampler.z_seed, config.sampler.z)
  return TrainSetup(seed=seed, extent=float(extent), spec=spec,
                    init_scales=init_scales(config.sampler, extent, GROUPS),
                    step_config=step_config, num_steps=num_steps, sobol=sobol)


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


def views_for_step(seed, step, num_views, batch_size):
  """The step's index into the views: `view_for_step(step)` (int32) for one view per step;
  with B > 1, the [B] views at positions step B .. step B + B - 1 of the same order."""
  if batch_size == 1:
    return jnp.int32(view_for_step(seed, step, num_views))
  first = int(step) * batch_size
  return jnp.asarray([view_for_step(seed, p, num_views)
                      for p in range(first, first + batch_size)], jnp.int32)


def step_sobol(setup: TrainSetup, step):
  """The Sobol rows of `step`: [M, k], or [B, M, k] (each target's) with a batch."""
  m, b = setup.step_config.num_samples, setup.step_config.batch_size
  rows = setup.sobol[step * b * m:(step + 1) * b * m]
  return rows if b == 1 else rows.reshape(b, m, rows.shape[-1])


# ------------------------------------------------------------------------- training


def checkpoint_meta(state, setup: TrainSetup, **extra):
  """A checkpoint's metadata: step, capacity and render budget (what `restore_latest` needs
  to rebuild the state and its settings), and `extra` (the caller's record)."""
  return {"step": int(state.step), "capacity": int(state.model.capacity),
          "max_intersections": int(setup.step_config.settings.max_intersections), **extra}


def _meta(config, setup, state, history, train_seconds):
  return checkpoint_meta(
      state, setup, seed=setup.seed, sobol_seed=int(config.sampler.z_seed),
      sobol_position=int(state.step) * setup.step_config.batch_size
      * setup.step_config.num_samples, extent=setup.extent,
      history=history, train_seconds=train_seconds, config=resumable_config(config))


def restore_latest(directory, setup: TrainSetup, initial_state, check=None):
  """(state, setup, meta) from the newest intact checkpoint in `directory`, or None if none.

  Works for every field. An unreadable checkpoint (truncated, overwritten) is reported with a
  warning naming it, and the next older one is tried; a later save replaces it.

  Args:
    directory: the checkpoint folder.
    setup: the run's `TrainSetup`; the returned one renders with the checkpoint's budget.
    initial_state: () -> the run's step-0 `TrainState`, the template of the saved one (grown
      to the checkpoint's capacity).
    check: optional (meta, path) -> None that refuses a checkpoint of another run by raising
      (`train_and_evaluate`'s: another config or seed).

  Raises:
    ckpt.CorruptCheckpointError: checkpoints exist but none can be read.
  """
  paths = ckpt.list_checkpoints(directory)
  if not paths:
    return None
  unreadable = []
  for path in reversed(paths):
    try:
      meta = ckpt.read_meta(path)
      if check is not None:
        check(meta, path)
      template = densify_lib.grow_capacity(initial_state(), meta["capacity"])
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

  Raises:
    BudgetExceededError: the step needs more than `max_budget` (config.render.max_budget).
  """
  settings = fit_budget(setup.step_config.settings, metrics)
  if settings.max_intersections > max_budget:
    raise BudgetExceededError(
        f"step {step} needs {int(metrics.num_padded)} intersections, more than "
        f"config.render.max_budget={max_budget}")
  return setup._replace(step_config=dataclasses.replace(setup.step_config, settings=settings))


def host_events(config, setup, state, step):
  """Densification and opacity reset after `step` completed steps (3DGS's schedule,
  `config.densify`); returns (state, the densification's report or None)."""
  d = config.densify
  report = None
  if d.start < step < d.stop and step % d.every == 0:
    state, report = densify_lib.densify_and_prune(
        state, rng=np.random.default_rng([setup.seed, 2, step]),
        grad_threshold=d.grad_threshold, percent_dense=d.percent_dense, extent=setup.extent,
        min_opacity=d.min_opacity, init_scales=setup.init_scales,
        max_gaussians=config.model.max_gaussians, prune_big=step > d.prune_big_after,
        max_screen_size=d.max_screen_size, max_world_size=d.max_world_size)
  # 3DGS resets opacities at the start of densification on a white background too.
  white = all(c == 1.0 for c in setup.step_config.background)
  if step < d.stop and (step % d.opacity_reset_every == 0 or (white and step == d.start)):
    state = densify_lib.reset_opacity(state)
  return state, report


class StepDone(NamedTuple):
  """What `run_steps` yields after every completed step."""

  state: TrainState
  setup: TrainSetup  # with the render budget that sufficed
  metrics: StepMetrics
  report: object  # the densification report of this step, or None


def run_steps(config, setup: TrainSetup, state, data, *, pick, end, max_traces=None):
  """Runs the jitted step from `state.step` to `end`, on any field.

  A step that overflows its render budget changed nothing: the budget grows
  (`config.render.max_budget` at most) and the step runs again. After every completed step
  the host events of 3DGS run (`host_events`).

  With a batch split over several devices (`StepConfig.num_devices` > 1) `data` is placed on
  every one of them once, and the yielded states are replicated over them
  (`sharding.host_local` brings one back to this process alone).

  Args:
    config: a config with `densify`, `model.max_gaussians` and `render.max_budget` (a
      training config, or the light-planning config).
    setup: `TrainSetup` (its `field` says what `data` and the indices are).
    state: `TrainState`.
    data: the field's training data, device arrays (`ColourField`: (images, cameras)).
    pick: step -> the step's index into `data` (a function of the seed and the step, so
      that a resumed run draws the same); with `StepConfig.batch_size` B > 1, the B
      targets (a leading [B] axis on every leaf).
    end: stop when this many steps are done in total.
    max_traces: passed to `make_train_step` (tests: 1).

  Yields:
    `StepDone` after every completed step.

  Raises:
    mfsample.interrupts.Interrupted: a stop was requested (between two steps).
  """
  step_fn = make_train_step(setup.step_config, setup.field, max_traces)
  # On the step's devices once (not copied there at every call), the state in the placement
  # the step returns it in (an input placed otherwise would compile the step a second time).
  place = lambda tree: sharding.replicated(tree, setup.step_config.num_devices)  # noqa: E731
  data, state = place(data), place(state)
  step = int(state.step)
  while step < end:
    interrupts.check(f"at step {step}")  # a safe point: between two steps
    new_state, metrics = step_fn(state, data, pick(step), step_sobol(setup, step))
    if bool(metrics.overflow):  # nothing was updated: grow the budget and redo the step
      setup = with_grown_budget(setup, metrics, int(config.render.max_budget), step)
      step_fn = make_train_step(setup.step_config, setup.field, max_traces)
      continue
    state, step = new_state, step + 1
    state, report = host_events(config, setup, state, step)
    state = place(state)  # (densification builds new arrays on the host)
    yield StepDone(state, setup, metrics, report)


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
    restored = restore_latest(
        checkpoint_dir, setup, lambda: init_state(config, setup, bounds, points),
        check=lambda meta, path: _check_checkpoint_config(config, setup, meta, path))
    if restored is not None:
      state, setup, meta = restored
      history = list(meta.get("history", []))
      seconds_before = float(meta.get("train_seconds", 0.0))
  if state is None:
    state = init_state(config, setup, bounds, points)
  views = data_lib.to_device(views)
  step = int(state.step)
  end = setup.num_steps if stop_at is None else min(stop_at, setup.num_steps)
  num_views = len(views) if num_views is None else int(num_views)
  bar = tqdm(total=setup.num_steps, initial=step,
             disable=not (config.train.progress and distributed.is_writer()),
             desc=f"train {setup.spec.kind}", dynamic_ncols=True)
  t0 = time.perf_counter()
  batch = setup.step_config.batch_size
  pick = lambda s: views_for_step(setup.seed, s, num_views, batch)  # noqa: E731
  steps = run_steps(config, setup, state, (views.images, views.cameras), pick=pick, end=end,
                    max_traces=max_traces)
  saved = step
  while True:
    try:
      done = next(steps)
    except StopIteration:
      break
    except interrupts.Interrupted:
      if checkpoint_dir and saved != step:  # the steps done so far are kept
        meta = _meta(config, setup, state, history, seconds_before + time.perf_counter() - t0)
        ckpt.save_checkpoint(checkpoint_dir, state, meta, keep=config.train.keep_checkpoints)
      bar.close()
      raise
    state, setup, metrics = done.state, done.setup, done.metrics
    step = int(state.step)
    if step % config.train.log_every == 0 or step == end:
      entry = {"step": step, "loss": float(metrics.loss), "data_loss": float(metrics.data_loss),
               "volume": float(metrics.volume), "live": state.model.num_live,
               "capacity": state.model.capacity,
               "budget": setup.step_config.settings.max_intersections,
               "seconds": seconds_before + time.perf_counter() - t0}
      if done.report is not None:
        entry["densify"] = done.report._asdict()
      history.append(entry)
      bar.set_postfix(loss=f"{entry['data_loss']:.4f}", n=entry["live"])
    bar.update(1)
    if checkpoint_dir and (step % config.train.checkpoint_every == 0
                           or (step == setup.num_steps)):
      meta = _meta(config, setup, state, history, seconds_before + time.perf_counter() - t0)
      ckpt.save_checkpoint(checkpoint_dir, state, meta, keep=config.train.keep_checkpoints)
      saved = step
  bar.close()
  seconds = time.perf_counter() - t0
  if setup.step_config.num_devices > 1:
    state = sharding.host_local(state)  # free to be used on any mesh from here on
  return TrainResult(state, setup, history, seconds, seconds_before + seconds)
