"""Training a relightable field on (view, light) captures: its setup and phases.

The cameras are fixed and the lights grow. The step and the loop are the colour field's
(`mfsample.train.step.train_step`, `mfsample.train.loop.run_steps`) with the relightable
field as their `Field` (`field.RelightableField`): each step draws one (view, light) pair,
renders M samples theta(z) of the field under that light into that view and takes the
gradient of the paper's Eq. 9 loss on the linear radiance, then Adam with per-group learning
rates, B_hat clamped into its bounds, and the 3DGS densification statistics accumulated;
the host densifies on schedule, and an overflowing render grows the budget and reruns the
step. The step's static settings are a `StepConfig` whose background is black and whose SH
schedule is unused.

Pairs are drawn in epochs of random permutations of the current (view, light) pairs, seeded
by (seed, phase start, epoch): every pair is seen equally often, and every strategy of a
planning run sees the same sequence of (view, light slot) pairs. Images of all lights live in
one array [L_max, V, H, W, 3] padded to the protocol's number of lights, so one compilation
serves every phase and every strategy. Checkpoints are the colour field's
(`mfsample.train.checkpoint`), restored with its fallback to an older intact one.
"""

import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample.data.datasets import scene_extent
from mfsample.lighting import field
from mfsample.train import checkpoint as ckpt
from mfsample.train import optim
from mfsample.train.config import render_settings
from mfsample.train.loop import (
    TrainSetup,
    checkpoint_meta,
    init_scales,
    restore_latest,
    run_steps,
    sampler_spec,
    sobol_rows,
)
from mfsample.train.step import StepConfig, TrainState, init_train_state


def make_setup(config, train_cameras, total_steps) -> TrainSetup:
  """`TrainSetup` of a relightable field from a light-planning config.

  Args:
    config: the config (its `model`, `sampler`, `optim`, `loss`, `densify`, `render`).
    train_cameras: `Camera` [V] (the scene extent when `model.extent` is None).
    total_steps: steps of the whole run (the learning-rate decay spans them).
  """
  m, n = int(config.model.out_coeffs), int(config.model.light_coeffs)
  shapes = field.group_shapes(m, n)
  extent = config.model.extent
  extent = scene_extent(train_cameras) if extent is None else float(extent)
  s = config.sampler
  spec = sampler_spec(s, extent, shapes)
  o = config.optim
  rates = optim.LearningRates(
      position=(float(o.position_lr_init) * extent, float(o.position_lr_final) * extent,
                int(total_steps)),
      mean=tuple((g, float(o[g])) for g in shapes if g != "means"),
      spread=tuple((g, float(s.lr[g]) * (extent if g == "means" else 1.0))
                   for g in spec.groups))
  step_config = StepConfig(
      settings=render_settings(config.render), background=(0.0, 0.0, 0.0),
      num_samples=int(s.num_samples), ssim_weight=float(config.loss.ssim_weight),
      volume_weight=float(config.loss.volume_weight),
      volume_every=int(config.loss.volume_every),
      volume_until=int(total_steps) - int(config.loss.volume_stop_before_end),
      stats_until=int(config.densify.stop), sh_degree_every=2**31 - 1,
      stochastic_until=2**31 - 1, rates=rates)
  return TrainSetup(int(config.seed), float(extent), spec, init_scales(s, extent, shapes),
                    step_config, int(total_steps),
                    sobol_rows(spec, int(total_steps) * step_config.num_samples, s.z_seed),
                    field.RelightableField(m, n))


def init_state(config, setup: TrainSetup, bounds):
  """The step-0 `TrainState`: `config.model.init_points` random points in the box `bounds`,
  T = 0."""
  rng = np.random.default_rng([setup.seed, 0])
  low, high = (np.asarray(b, np.float64) for b in bounds)
  points = rng.uniform(low, high, (int(config.model.init_points), 3))
  k_model, k_train = jax.random.split(jax.random.PRNGKey(setup.seed))
  model = field.init_relightable(k_model, points, spec=setup.spec,
                                 out_coeffs=setup.field.out_coeffs,
                                 light_coeffs=setup.field.light_coeffs,
                                 init_scales=setup.init_scales,
                                 init_opacity=float(config.model.init_opacity))
  return init_train_state(model, setup.step_config, k_train)


def pair_for_step(seed, step, phase_start, num_views, num_lights):
  """(light slot, view) of `step`: epochs of random permutations of the V x l pairs."""
  pairs = int(num_views) * int(num_lights)
  epoch, within = divmod(int(step) - int(phase_start), pairs)
  index = int(np.random.default_rng([int(seed), 3, int(phase_start), epoch])
              .permutation(pairs)[within])
  return divmod(index, int(num_views))


class PhaseResult(NamedTuple):
  state: TrainState
  setup: TrainSetup  # with the budget that sufficed
  seconds: float
  data_loss: float  # mean data loss over the phase's steps


def train_steps(config, setup: TrainSetup, state, images, lights, cameras, *, num_lights,
                phase_start, end, max_traces=None, on_step=None) -> PhaseResult:
  """Trains from `state.step` to `end` on the first `num_lights` light slots.

  Args:
    config: the light-planning config (`densify`, `model.max_gaussians`, `render.max_budget`).
    setup: `TrainSetup` of the relightable field (`make_setup`).
    state: `TrainState`.
    images: [L_max, V, H, W, 3] device array of captures (slots >= num_lights unused).
    lights: [L_max, n] device array.
    cameras: `Camera` [V] with jnp leaves.
    num_lights: lights in use (>= 1).
    phase_start: the step at which this set of lights started (seeds the pair order).
    end: stop when this many steps are done in total.
    max_traces: see `mfsample.train.step.make_train_step`.
    on_step: optional callback(step) after every step (progress bars).
  """
  num_views = cameras.world_to_camera.shape[0]

  def pick(step):
    light, view = pair_for_step(setup.seed, step, phase_start, num_views, num_lights)
    return jnp.int32(light), jnp.int32(view)

  losses_sum, count = 0.0, 0
  t0 = time.perf_counter()
  for done in run_steps(config, setup, state, (images, lights, cameras), pick=pick, end=end,
                        max_traces=max_traces):
    state, setup = done.state, done.setup
    losses_sum += float(done.metrics.data_loss)
    count += 1
    if on_step is not None:
      on_step(int(state.step))
  return PhaseResult(state, setup, time.perf_counter() - t0,
                     losses_sum / count if count else float("nan"))


# ------------------------------------------------------------------------- checkpoints


def save_state(directory, state, setup: TrainSetup, meta):
  """Writes `state` with `meta` (+ step, capacity and render budget) as one atomic
  checkpoint."""
  return ckpt.save_checkpoint(directory, state, checkpoint_meta(state, setup, **meta), keep=1)


def restore_state(directory, config, setup: TrainSetup, bounds):
  """(state, setup with the saved budget, meta) of the newest intact checkpoint, or None.

  Raises:
    ckpt.CorruptCheckpointError: checkpoints exist but none can be read (the protocol then
      trains the phase again).
  """
  return restore_latest(directory, setup, lambda: init_state(config, setup, bounds))
