"""The host loop of training: `fit` (the library's), `run_training` (with checkpoints), and the
pieces of a custom loop.

The loop is thin: it picks the targets of each step (a function of (seed, step): with B
targets per step, the targets at positions tB .. tB + B - 1 of one order of epochs of random
permutations), calls the jitted step, grows the render budget when a step reports overflow
(the step left the state untouched, so it is simply run again), and runs the host events of
3DGS (densification, opacity reset) between steps (`run_steps`, shared by the colour and the
relightable field). `run_training` adds the history, the progress bar and checkpoints.

Everything random is a function of the seed and the step, so equal inputs give
bit-identical results, and a resumed run continues exactly where a killed one stopped.
Resuming is safe: a checkpoint written with other settings, another sampler or another seed
is refused, naming what differs; a checkpoint that cannot be read is reported by path and
the newest intact one is used instead (`restore_latest`, for every field).

A custom loop (`docs/api.md`) uses the same pieces:

  setup = make_setup(settings, model, seed=0, extent=..., num_views=len(views))
  state = init_state(model, setup)
  step = make_train_step(setup.step_config)
  for t in range(settings.num_steps):
    state, metrics = step(state, (views.images, views.cameras),
                          *step_targets(setup, t, len(views)))
"""

import dataclasses
import json
import math
import time
import warnings
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks, distributed, interrupts, sharding
from mfsample import workdir as workdir_lib
from mfsample.data.datasets import scene_extent, to_device
from mfsample.data.views import Views
from mfsample.model import Model, check_model
from mfsample.renderer.budget import BudgetExceededError, fit_budget
from mfsample.samplers import sobol_rows
from mfsample.train import checkpoint as ckpt
from mfsample.train import densify as densify_lib
from mfsample.train import optim
from mfsample.train.settings import NEVER, TrainSettings
from mfsample.train.step import (
    COLOUR,
    StepConfig,
    StepMetrics,
    TrainState,
    init_train_state,
    make_train_step,
)


class TrainSetup(NamedTuple):
  """A run's settings resolved for its model, views and seed (host-side constants).

  Attributes:
    settings: the `TrainSettings` given (their render budget: where the run started).
    seed: seeds the view order, the step keys and densification.
    extent: the scene extent (world units).
    step_config: the jitted step's static `StepConfig` (its render budget grows).
    sobol: [num_steps * B * M, k] the steps' Sobol z rows ([.., 0] for uniform z).
    init_scales: {group: scale} of the fresh B_hat entries of densification.
    field: the step's `Field` (static): colour, or relightable.
  """

  settings: TrainSettings
  seed: int
  extent: float
  step_config: StepConfig
  sobol: np.ndarray
  init_scales: dict
  field: object = COLOUR

  @property
  def num_steps(self):
    return self.settings.num_steps

  def with_settings(self, render_settings):
    """This setup whose step renders with `render_settings` (a budget that sufficed)."""
    return self._replace(step_config=self.step_config.with_settings(render_settings))


class TrainResult(NamedTuple):
  """What `run_training` returns."""

  state: TrainState
  setup: TrainSetup  # with the render budget that sufficed
  # Dicts logged every `settings.log_every` steps, from step 0: a resumed run carries the
  # log of the checkpoint it started from, so nothing is lost or logged twice.
  history: list
  seconds: float  # wall-clock of the steps run in this call (compilation included)
  train_seconds: float  # wall-clock of all the steps, summed over resumed segments


# ------------------------------------------------------------------------- setup


def make_setup(settings: TrainSettings, model: Model, *, seed, extent, num_views,
               field=COLOUR) -> TrainSetup:
  """The `TrainSetup` of training `model` with `settings`.

  Args:
    settings: `TrainSettings`.
    model: the step-0 model (its groups and sampler spec).
    seed: integer seed of the run.
    extent: scene extent (world units): scales the centres' rates and densification.
    num_views: training views (lambda = 1 / num_views when `settings.loss.volume_weight`
      is None).
    field: the step's `Field`.
  """
  arg_checks.check_seed("seed", seed)
  extent = arg_checks.check_float("extent", extent, above=0.0)
  num_views = arg_checks.check_int("num_views", num_views, minimum=1)
  s = settings
  volume_weight = s.loss.volume_weight
  if volume_weight is None:
    volume_weight = 1.0 / num_views
  rates = optim.learning_rates(s.optim, extent, s.optim.position_lr_max_steps or s.num_steps,
                               tuple(model.params.mean))
  step_config = StepConfig(
      settings=s.render, background=s.background, num_samples=s.num_samples,
      ssim_weight=s.loss.ssim_weight, volume_weight=float(volume_weight),
      volume_every=s.loss.volume_every,
      volume_until=s.num_steps - s.loss.volume_stop_before_end,
      stats_until=s.densify.stop, sh_degree_every=s.sh_degree_every,
      stochastic_until=NEVER if s.stochastic_until is None else s.stochastic_until,
      rates=rates, train_mean=s.train_mean, batch_size=s.batch_size,
      # B = 1 runs on one device (in every process alike).
      num_devices=1 if s.batch_size == 1 else sharding.default_num_devices(s.batch_size))
  sobol = sobol_rows(model.spec, s.num_steps * s.batch_size * s.num_samples, s.z_seed)
  return TrainSetup(s, int(seed), float(extent), step_config, sobol,
                    s.b_hat_init_scales(extent), field)


def init_state(model: Model, setup: TrainSetup) -> TrainState:
  """The step-0 `TrainState` of `model`: Adam's moments zero, the step keys from the seed."""
  _, key = jax.random.split(jax.random.PRNGKey(setup.seed))
  return init_train_state(model, setup.step_config, key)


def view_for_step(seed, step, num_views):
  """The training view of `step`: epochs of random permutations (3DGS), seeded per epoch."""
  epoch, within = divmod(int(step), num_views)
  return int(np.random.default_rng([int(seed), 1, epoch]).permutation(num_views)[within])


def step_targets(setup: TrainSetup, step, num_views):
  """(index [B] int32, rows [B, M, k]) of `step`: the views at positions step B .. step B + B
  - 1 of the order of `view_for_step`, and their Sobol z rows (`train_step`'s arguments)."""
  b = setup.settings.batch_size
  first = int(step) * b
  index = jnp.asarray([view_for_step(setup.seed, p, num_views)
                       for p in range(first, first + b)], jnp.int32)
  return index, step_rows(setup, step)


def step_rows(setup: TrainSetup, step):
  """[B, M, k] the Sobol rows of the B targets of `step`."""
  b, m = setup.settings.batch_size, setup.settings.num_samples
  rows = setup.sobol[int(step) * b * m:(int(step) + 1) * b * m]
  return rows.reshape(b, m, rows.shape[-1])


# ------------------------------------------------------------------------- the steps


def with_grown_budget(setup: TrainSetup, metrics: StepMetrics, step) -> TrainSetup:
  """`setup` whose step renders with a budget that holds the overflowing step's intersections.

  Raises:
    BudgetExceededError: the step needs more than `settings.max_budget`.
  """
  settings = fit_budget(setup.step_config.settings, metrics)
  if settings.max_intersections > setup.settings.max_budget:
    raise BudgetExceededError(
        f"step {step} needs {int(metrics.num_padded)} intersections, more than "
        f"max_budget={setup.settings.max_budget}")
  return setup.with_settings(settings)


def host_events(setup: TrainSetup, state, step):
  """Densification and opacity reset after `step` completed steps (3DGS's schedule,
  `settings.densify`); returns (state, the densification's report or None)."""
  d = setup.settings.densify
  report = None
  if d.start < step < d.stop and step % d.every == 0:
    state, report = densify_lib.densify_and_prune(
        state, rng=np.random.default_rng([setup.seed, 2, step]),
        grad_threshold=d.grad_threshold, percent_dense=d.percent_dense, extent=setup.extent,
        min_opacity=d.min_opacity, init_scales=setup.init_scales,
        max_gaussians=d.max_gaussians, prune_big=step > d.prune_big_after,
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


def run_steps(setup: TrainSetup, state, data, *, pick: Callable, end, max_traces=None):
  """Runs the jitted step from `state.step` to `end`, on any field.

  A step that overflows its render budget changed nothing: the budget grows
  (`settings.max_budget` at most) and the step runs again. After every completed step the
  host events of 3DGS run (`host_events`).

  With a batch split over several devices (`StepConfig.num_devices` > 1) `data` is placed on
  every one of them once, and the yielded states are replicated over them
  (`sharding.host_local` brings one back to this process alone).

  Args:
    setup: `TrainSetup` (its `field` says what `data` and the targets are).
    state: `TrainState`.
    data: the field's training data, device arrays (`ColourField`: (images, cameras)).
    pick: step -> (the step's B targets in `data`, a leading [B] axis on every leaf; their
      Sobol rows [B, M, k]), a function of the seed and the step so that a resumed run draws
      the same (`step_targets`).
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
    new_state, metrics = step_fn(state, data, *pick(step))
    if bool(metrics.overflow):  # nothing was updated: grow the budget and redo the step
      setup = with_grown_budget(setup, metrics, step)
      step_fn = make_train_step(setup.step_config, setup.field, max_traces)
      continue
    state, step = new_state, step + 1
    state, report = host_events(setup, state, step)
    state = place(state)  # (densification builds new arrays on the host)
    yield StepDone(state, setup, metrics, report)


# ------------------------------------------------------------------------- checkpoints

# Render settings that change only how fast a run goes, never what it computes (beyond float
# rounding): a resumed run may differ in them. The budget among them: it grows as a run goes,
# and a render that fits gives the same image whatever its budget.
SPEED_ONLY_RENDER = ("chunks_per_step", "compositor", "searchsorted_method",
                     "skip_unused_steps", "pallas_warps", "max_intersections")


def settings_record(settings: TrainSettings):
  """`settings` as a JSON dict, less the speed-only render fields (what checkpoints record
  and a resumed run must match)."""
  record = json.loads(json.dumps(dataclasses.asdict(settings)))
  for name in SPEED_ONLY_RENDER:
    record["render"].pop(name, None)
  return record


def checkpoint_meta(state, setup: TrainSetup, **extra):
  """A checkpoint's metadata: step, capacity, render budget and sampler spec (what
  `restore_latest` and a viewer need to rebuild the state and its model), and `extra`."""
  return {"step": int(state.step), "capacity": int(state.model.capacity),
          "max_intersections": int(setup.step_config.settings.max_intersections),
          "sampler": state.model.spec.to_dict(), **extra}


def restore_latest(directory, setup: TrainSetup, initial_state: Callable, check=None):
  """(state, setup, meta) from the newest intact checkpoint in `directory`, or None if none.

  Works for every field. An unreadable checkpoint (truncated, overwritten) is reported with a
  warning naming it, and the next older one is tried; a later save replaces it.

  Args:
    directory: the checkpoint folder.
    setup: the run's `TrainSetup`; the returned one renders with the checkpoint's budget.
    initial_state: () -> the run's step-0 `TrainState`, the template of the saved one (grown
      to the checkpoint's capacity).
    check: optional (meta, path) -> None that refuses a checkpoint of another run by raising.

  Raises:
    ckpt.CorruptCheckpointError: checkpoints exist but none can be read.
  """
  if not ckpt.list_checkpoints(directory):
    return None

  def read(path):
    meta = ckpt.read_meta(path)
    if check is not None:
      check(meta, path)
    template = densify_lib.grow_capacity(initial_state(), meta["capacity"])
    return ckpt.restore_checkpoint(path, template)

  path, restored, unreadable = ckpt.newest_readable(directory, read)
  for _, e in unreadable:
    warnings.warn(f"{e}; trying an older checkpoint", stacklevel=2)
  if path is None:
    raise ckpt.CorruptCheckpointError(
        f"no readable checkpoint in {directory}: {'; '.join(str(e) for _, e in unreadable)}. "
        "Remove them to train from scratch.")
  state, meta = restored
  # Rounded: the checkpoint's run may have composited more or fewer chunks per step.
  settings = setup.step_config.settings.holding_budget(meta["max_intersections"])
  return state, setup.with_settings(settings), meta


def _same_record(a, b, rel=1e-6):
  """Equal JSON records, floats to `rel` (a bound derived from the scene's extent is a few
  float32 roundings apart when another version or XLA setting computed it)."""
  if isinstance(a, float) or isinstance(b, float):
    return (isinstance(a, (int, float)) and isinstance(b, (int, float))
            and math.isclose(a, b, rel_tol=rel, abs_tol=0.0))
  if isinstance(a, dict) and isinstance(b, dict):
    return a.keys() == b.keys() and all(_same_record(a[k], b[k], rel) for k in a)
  if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
    return len(a) == len(b) and all(_same_record(x, y, rel) for x, y in zip(a, b, strict=True))
  return a == b


def _check_same_run(setup: TrainSetup, spec, meta, path):
  """Refuses a checkpoint written with another seed, sampler or (where recorded) settings."""
  if meta.get("seed") != setup.seed:
    raise workdir_lib.WorkdirError(
        f"{path} was written by a run with seed {meta.get('seed')}, this run has seed "
        f"{setup.seed}: use another checkpoint directory")
  if "sampler" in meta and not _same_record(meta["sampler"], spec.to_dict()):
    raise workdir_lib.WorkdirError(
        f"{path} was written by a run with another sampler ({meta['sampler']}, this run: "
        f"{spec.to_dict()}): use another checkpoint directory")
  if "settings" in meta:
    new = settings_record(setup.settings)
    if meta["settings"] != new:
      raise workdir_lib.WorkdirError(
          f"{path} was written by a run with different training settings (differences: "
          f"{', '.join(workdir_lib.differences(meta['settings'], new))}): use another "
          "checkpoint directory")


# ------------------------------------------------------------------------- training


def _check_views(views, model):
  if not isinstance(views, Views):
    raise ValueError(f"views must be mfsample.data.Views, got {type(views).__name__}")
  views.validate()
  # Training syncs anyway: a model with a NaN parameter or B_hat beyond its bound is named
  # here, not trained (the renderer would cull its broken Gaussians silently).
  check_model(model, sync=True)


def _progress_bar(show, **kwargs):
  """A tqdm bar; a hidden one is the plain bar, since `tqdm.auto` in a notebook without
  ipywidgets warns even for a bar that is never shown."""
  if show:
    from tqdm.auto import tqdm
  else:
    from tqdm import tqdm
  return tqdm(disable=not show, dynamic_ncols=True, **kwargs)


def run_training(model: Model, views: Views, settings: TrainSettings, *, seed, extent=None,
                 state=None, num_views=None, stop_at=None, checkpoint_dir=None,
                 checkpoint_every=500, keep_checkpoints=2, record=None, progress=False,
                 max_traces=None) -> TrainResult:
  """Trains `model` on `views` (`fit`, with checkpoints, resume and the whole record).

  Args:
    model: the step-0 `Model` (`mfsample.init_model`; the template of a resumed state).
    views: training `Views`.
    settings: `TrainSettings` (`settings.num_steps` sets the length).
    seed: integer seed of the view order, the step keys and densification.
    extent: scene extent (default: `settings.extent`, else 3DGS's, from the cameras).
    state: optional `TrainState` to continue from (default: the newest checkpoint in
      `checkpoint_dir`, else a fresh one).
    num_views: draw the step's views among the first `num_views` of `views` only (default:
      all). Callers that pad `views` to a fixed count keep one compilation of the step
      while the number of real views grows (planning rounds).
    stop_at: stop after this many steps in total, without a final checkpoint (a run to
      continue later from the returned state, or as a killed run would stop).
    checkpoint_dir: if set, resume from and write checkpoints there.
    checkpoint_every: checkpoint period in steps (and at the end).
    keep_checkpoints: older checkpoints are deleted.
    record: JSON-able dict every checkpoint carries (the caller's).
    progress: show a tqdm progress bar (by the writing process).
    max_traces: passed to `make_train_step` (tests: 1).

  Returns:
    `TrainResult`.
  """
  _check_views(views, model)
  checkpoint_every = arg_checks.check_int("checkpoint_every", checkpoint_every, minimum=1)
  keep_checkpoints = arg_checks.check_int("keep_checkpoints", keep_checkpoints, minimum=1)
  if stop_at is not None:
    arg_checks.check_int("stop_at", stop_at, minimum=0)
  num_views = len(views) if num_views is None else arg_checks.check_int(
      "num_views", num_views, minimum=1, maximum=len(views))
  if extent is None:
    extent = settings.extent if settings.extent is not None else scene_extent(
        views.subset(range(num_views)).cameras)
  setup = make_setup(settings, model, seed=seed, extent=extent, num_views=num_views)
  spec = model.spec
  history, seconds_before = [], 0.0
  if state is None and checkpoint_dir:
    restored = restore_latest(checkpoint_dir, setup, lambda: init_state(model, setup),
                              check=lambda meta, path: _check_same_run(setup, spec, meta, path))
    if restored is not None:
      state, setup, meta = restored
      history = list(meta.get("history", []))
      seconds_before = float(meta.get("train_seconds", 0.0))
  if state is None:
    state = init_state(model, setup)
  data = to_device(views)
  step = int(state.step)
  end = settings.num_steps if stop_at is None else min(int(stop_at), settings.num_steps)
  bar = _progress_bar(progress and distributed.is_writer(), total=settings.num_steps,
                      initial=step, desc=f"train {spec.kind}")
  t0 = time.perf_counter()

  def meta():
    return checkpoint_meta(state, setup, seed=setup.seed, extent=setup.extent,
                           history=history, settings=settings_record(settings),
                           train_seconds=seconds_before + time.perf_counter() - t0,
                           **(record or {}))

  steps = run_steps(setup, state, (data.images, data.cameras),
                    pick=lambda s: step_targets(setup, s, num_views), end=end,
                    max_traces=max_traces)
  saved = step
  while True:
    try:
      done = next(steps)
    except StopIteration:
      break
    except interrupts.Interrupted:
      if checkpoint_dir and saved != step:  # the steps done so far are kept
        ckpt.save_checkpoint(checkpoint_dir, state, meta(), keep=keep_checkpoints)
      bar.close()
      raise
    state, setup, metrics = done.state, done.setup, done.metrics
    step = int(state.step)
    if step % settings.log_every == 0 or step == end:
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
    if checkpoint_dir and (step % checkpoint_every == 0 or step == settings.num_steps):
      ckpt.save_checkpoint(checkpoint_dir, state, meta(), keep=keep_checkpoints)
      saved = step
  bar.close()
  seconds = time.perf_counter() - t0
  if setup.step_config.num_devices > 1:
    state = sharding.host_local(state)  # free to be used on any mesh from here on
  return TrainResult(state, setup, history, seconds, seconds_before + seconds)


def fit(model: Model, views: Views, settings: TrainSettings = TrainSettings(), *,
        key: jax.Array, **kwargs) -> tuple[Model, list]:
  """Trains a stochastic field on `views`: the paper's training (Sec. 4.3), no files.

  Each step renders `settings.num_samples` samples theta(z) = mean + B_hat z of the model
  (z: the spec's source; Sobol for the low-rank sampler) into `settings.batch_size` training
  views and takes an Adam step on Eq. 9, (1 - w) L1 + w (1 - SSIM) less lambda ||B_hat||_1
  (every `loss.volume_every`-th step), with 3DGS's per-group learning rates and adaptive
  density control (`settings.densify`). The render budget grows on overflow (never a
  truncated image). Deterministic in `key`.

  Args:
    model: the step-0 `Model` ([C] rows; `mfsample.init_model`), any sampler kind.
    views: training `Views` (images [V, H, W, 3] composited on `settings.background`).
    settings: `TrainSettings`.
    key: a JAX PRNG key (the view order, the step keys, densification).
    **kwargs: `run_training`'s (`extent`, `num_views`, `stop_at`, `progress`,
      `checkpoint_dir`, ...).

  Returns:
    (the trained `Model` (capacity may have grown), history: a list of dicts every
    `settings.log_every` steps: step, loss, data_loss, volume, live, capacity, budget,
    seconds).
  """
  if not isinstance(settings, TrainSettings):
    raise ValueError(f"settings must be a TrainSettings, got {type(settings).__name__}")
  arg_checks.check_key(key)
  seed = int(jax.random.randint(key, (), 0, np.iinfo(np.int32).max))
  result = run_training(model, views, settings, seed=seed, **kwargs)
  return result.state.model, result.history
