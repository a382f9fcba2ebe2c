"""Training a relightable field on (view, light) captures: the jitted step and a thin loop.

The cameras are fixed and the lights grow. Each step draws one (view, light) pair, renders M
samples theta(z) of the field under that light into that view (`field.render_relit`) and
takes the gradient of the paper's Eq. 9 loss (`mfsample.train.losses`: (1 - w) L1 + w D-SSIM
on the linear radiance, minus lambda ||B_hat||_1 every `volume_every`-th step), then Adam
with per-group learning rates (`mfsample.train.optim`), B_hat clamped into its bounds, and
the 3DGS densification statistics accumulated; the host densifies on schedule with
`mfsample.train.densify`. If a render overflows its intersection budget the step returns
the unchanged state and the host grows the budget and re-runs it, as
`mfsample.train.step.train_step` does. The step's static settings are the colour step's
`StepConfig` (its `background` is black and `sh_degree_every` unused).

Pairs are drawn in epochs of random permutations of the current (view, light) pairs, seeded
by (seed, phase start, epoch): every pair is seen equally often, and every strategy of a
planning run sees the same sequence of (view, light slot) pairs. Images of all lights live in
one array [L_max, V, H, W, 3] padded to the protocol's number of lights, so one compilation
serves every phase and every strategy.
"""

import dataclasses
import functools
import time
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax

from mfsample import samplers
from mfsample.data.datasets import scene_extent
from mfsample.lighting import field
from mfsample.model import SamplerSpec, project_spread
from mfsample.train import checkpoint as ckpt
from mfsample.train import densify as densify_lib
from mfsample.train import losses, optim
from mfsample.train.loop import render_settings, with_grown_budget
from mfsample.train.step import (
  DensifyStats,
  StepConfig,
  StepMetrics,
  TrainState,
  init_train_state,
  step_schedule,
)


class LightSetup(NamedTuple):
  """Host-side constants of a relightable training run.

  Attributes:
    seed: seeds the initial cloud, B_hat signs, step keys, pair order and densification.
    extent: scene extent (world units).
    spec: `SamplerSpec` of B_hat.
    init_scales: {group: float} scale of fresh B_hat entries.
    step_config: `StepConfig` (static settings of the jitted step, the render budget included).
    total_steps: steps of the whole run (the learning-rate decay spans them).
    sobol: [total_steps * M, k] z rows (empty unless lowrank + Sobol).
    out_coeffs: m.
    light_coeffs: n.
  """

  seed: int
  extent: float
  spec: SamplerSpec
  init_scales: dict
  step_config: StepConfig
  total_steps: int
  sobol: np.ndarray
  out_coeffs: int
  light_coeffs: int


def make_setup(config, train_cameras, total_steps):
  """`LightSetup` from a light-planning config (`mfsample.lighting.default_config()`).

  Args:
    config: the config (its `model`, `sampler`, `optim`, `loss`, `densify`, `render`).
    train_cameras: `Camera` [V] (the scene extent when `model.extent` is None).
    total_steps: steps of the whole run.
  """
  m, n = int(config.model.out_coeffs), int(config.model.light_coeffs)
  shapes = field.group_shapes(m, n)
  extent = config.model.extent
  extent = scene_extent(train_cameras) if extent is None else float(extent)
  s = config.sampler
  groups = tuple(g for g in s.groups if g in shapes)
  bounds = tuple((g, float(s.bounds[g]) * (extent if g == "means" else 1.0)) for g in groups)
  spec = SamplerSpec(kind=s.kind, rank=int(s.rank), groups=groups, bounds=bounds)
  init_scales = {g: float(s.init_scale) * (extent if g in s.init_extent_groups else 1.0)
                 for g in shapes}
  o = config.optim
  rates = optim.LearningRates(
      position=(float(o.position_lr_init) * extent, float(o.position_lr_final) * extent,
                int(total_steps)),
      mean=tuple((g, float(o[g])) for g in shapes if g != "means"),
      spread=tuple((g, float(s.lr[g]) * (extent if g == "means" else 1.0)) for g in groups))
  r = config.render
  settings = render_settings(r)
  step_config = StepConfig(
      settings=settings, background=(0.0, 0.0, 0.0), num_samples=int(s.num_samples),
      ssim_weight=float(config.loss.ssim_weight),
      volume_weight=float(config.loss.volume_weight),
      volume_every=int(config.loss.volume_every),
      volume_until=int(total_steps) - int(config.loss.volume_stop_before_end),
      stats_until=int(config.densify.stop), sh_degree_every=2**31 - 1,
      stochastic_until=2**31 - 1, rates=rates)
  k = step_config.num_samples
  if spec.kind == "lowrank" and spec.stochastic:
    sobol = samplers.sobol_z(int(total_steps) * k, spec.rank, int(s.z_seed))
  else:
    sobol = np.zeros((int(total_steps) * k, 0), np.float32)
  return LightSetup(int(config.seed), float(extent), spec, init_scales, step_config,
                    int(total_steps), sobol, m, n)


def init_state(config, setup: LightSetup, bounds):
  """The step-0 `TrainState`: `config.model.init_points` random points in the box `bounds`,
  T = 0."""
  rng = np.random.default_rng([setup.seed, 0])
  low, high = (np.asarray(b, np.float64) for b in bounds)
  points = rng.uniform(low, high, (int(config.model.init_points), 3))
  k_model, k_train = jax.random.split(jax.random.PRNGKey(setup.seed))
  model = field.init_relightable(k_model, points, spec=setup.spec,
                                 out_coeffs=setup.out_coeffs, light_coeffs=setup.light_coeffs,
                                 init_scales=setup.init_scales,
                                 init_opacity=float(config.model.init_opacity))
  return init_train_state(model, setup.step_config, k_train)


# ------------------------------------------------------------------------- the step


def _live_rows(tree, mask):
  """Zeros every [C, ...] leaf on the padding rows (they never move)."""
  return jax.tree.map(
      lambda x: jnp.where(mask.reshape((-1,) + (1,) * (x.ndim - 1)), x, jnp.zeros_like(x)),
      tree)


def relight_step(state: TrainState, images, lights, cameras, view, light, sobol_rows, *,
                 cfg: StepConfig):
  """One optimisation step on the capture of `view` under light slot `light` (pure).

  Args:
    state: `TrainState` of a relightable model.
    images: [L_max, V, H, W, 3] captures (linear radiance) of every light slot and view.
    lights: [L_max, n] the lights of the slots.
    cameras: `Camera` batched over V.
    view: int32 scalar.
    light: int32 scalar, the light slot.
    sobol_rows: [M, k] Sobol z's of this step (low rank; ignored otherwise).
    cfg: `StepConfig` (static).

  Returns:
    (new state, `StepMetrics`).
  """
  step = state.step
  model = state.model
  image = images[light, view]
  xi = lights[light]
  camera = cameras[view]
  z, volume_weight = step_schedule(cfg, model, state.key, step, sobol_rows)
  offset2d = jnp.zeros((model.capacity, 2), model.params.mean["means"].dtype)

  def loss_fn(params, offset2d):
    m = model.replace(params=params)

    def one(z_i):
      out = field.render_relit(samplers.perturb(m, z_i), m.mask, xi, camera,
                               settings=cfg.settings, screen_offset=offset2d)
      return losses.photometric(out.rgb, image, cfg.ssim_weight), (out.radii, out.visible,
                                                                    out.stats)

    if cfg.num_samples == 1:
      # A plain call keeps the renderer's cheap skipping of unused budget (vmap would not).
      data, aux = jax.tree.map(lambda x: x[None], one(z[0]))
    else:
      data, aux = jax.lax.map(one, z)
    data = jnp.mean(data)
    volume = losses.volume(m) if m.spec.stochastic else jnp.zeros((), data.dtype)
    return data - volume_weight * volume, (data, volume, aux)

  grad_fn = jax.value_and_grad(loss_fn, argnums=(0, 1), has_aux=True)
  (loss, (data, volume, (radii, visible, stats))), (grads, grad2d) = grad_fn(
      model.params, offset2d)
  updates, opt_state = cfg.optimizer.update(grads, state.opt_state, model.params)
  params = optax.apply_updates(model.params, _live_rows(updates, model.mask))
  params = params._replace(spread=project_spread(params.spread, model.spec))

  half_size = jnp.array([0.5 * camera.width, 0.5 * camera.height], grad2d.dtype)
  grad_norm = jnp.linalg.norm(grad2d * half_size, axis=-1)  # NDC units, as 3DGS
  seen = jnp.any(visible, axis=0) & (step < cfg.stats_until)
  new_stats = DensifyStats(
      grad_accum=state.stats.grad_accum + jnp.where(seen, grad_norm, 0.0),
      count=state.stats.count + seen.astype(jnp.int32),
      max_radii=jnp.where(seen, jnp.maximum(state.stats.max_radii, jnp.max(radii, axis=0)),
                          state.stats.max_radii))
  new_state = TrainState(step + 1, model.replace(params=params), opt_state, new_stats,
                         state.key)
  chex.assert_trees_all_equal_shapes_and_dtypes(state, new_state)
  overflow = jnp.any(stats.overflow)  # a void step: keep the old state (the host regrows)
  new_state = jax.tree.map(lambda old, new: jnp.where(overflow, old, new), state, new_state)
  return new_state, StepMetrics(loss=loss, data_loss=data, volume=volume, overflow=overflow,
                                num_padded=jnp.max(stats.num_padded))


relight_step_jit = jax.jit(relight_step, static_argnames=("cfg",))


def make_relight_step(cfg: StepConfig, max_traces=None):
  """`fn(state, images, lights, cameras, view, light, sobol_rows)`, jitted (`max_traces`: a
  separately jitted step wrapped in `chex.assert_max_traces`, for tests)."""
  if max_traces is None:
    return functools.partial(relight_step_jit, cfg=cfg)
  counted = chex.assert_max_traces(relight_step, n=max_traces)
  return functools.partial(jax.jit(counted, static_argnames=("cfg",)), cfg=cfg)


# ------------------------------------------------------------------------- the loop


def pair_for_step(seed, step, phase_start, num_views, num_lights):
  """(light slot, view) of `step`: epochs of random permutations of the V x l pairs."""
  pairs = int(num_views) * int(num_lights)
  epoch, within = divmod(int(step) - int(phase_start), pairs)
  index = int(np.random.default_rng([int(seed), 3, int(phase_start), epoch])
              .permutation(pairs)[within])
  return divmod(index, int(num_views))


def _host_events(config, setup, state, step):
  """3DGS densification and opacity reset after `step` completed steps (config.densify)."""
  d = config.densify
  if d.start < step < d.stop and step % d.every == 0:
    state, _ = densify_lib.densify_and_prune(
        state, rng=np.random.default_rng([setup.seed, 2, step]),
        grad_threshold=float(d.grad_threshold), percent_dense=float(d.percent_dense),
        extent=setup.extent, min_opacity=float(d.min_opacity), init_scales=setup.init_scales,
        max_gaussians=int(config.model.max_gaussians),
        prune_big=step > int(d.prune_big_after), max_screen_size=float(d.max_screen_size),
        max_world_size=float(d.max_world_size))
  if step < d.stop and step % int(d.opacity_reset_every) == 0:
    state = densify_lib.reset_opacity(state)
  return state


class PhaseResult(NamedTuple):
  state: TrainState
  setup: LightSetup  # with the budget that sufficed
  seconds: float
  data_loss: float  # mean data loss over the phase's steps


def train_steps(config, setup: LightSetup, state, images, lights, cameras, *, num_lights,
                phase_start, end, max_traces=None, on_step=None) -> PhaseResult:
  """Trains from `state.step` to `end` on the first `num_lights` light slots.

  Args:
    config: the light-planning config (`densify`, `model.max_gaussians`, `render.max_budget`).
    setup: `LightSetup`.
    state: `TrainState`.
    images: [L_max, V, H, W, 3] device array of captures (slots >= num_lights unused).
    lights: [L_max, n] device array.
    cameras: `Camera` [V] with jnp leaves.
    num_lights: lights in use (>= 1).
    phase_start: the step at which this set of lights started (seeds the pair order).
    end: stop when this many steps are done in total.
    max_traces: see `make_relight_step`.
    on_step: optional callback(step) after every step (progress bars).
  """
  step_fn = make_relight_step(setup.step_config, max_traces)
  m = setup.step_config.num_samples
  step = int(state.step)
  num_views = cameras.world_to_camera.shape[0]
  losses_sum, count = 0.0, 0
  t0 = time.perf_counter()
  while step < end:
    light, view = pair_for_step(setup.seed, step, phase_start, num_views, num_lights)
    new_state, metrics = step_fn(state, images, lights, cameras, jnp.int32(view),
                                 jnp.int32(light), setup.sobol[step * m:(step + 1) * m])
    if bool(metrics.overflow):  # nothing was updated: grow the budget and redo the step
      setup = with_grown_budget(setup, metrics, int(config.render.max_budget), step)
      step_fn = make_relight_step(setup.step_config, max_traces)
      continue
    state, step = new_state, step + 1
    losses_sum += float(metrics.data_loss)
    count += 1
    state = _host_events(config, setup, state, step)
    if on_step is not None:
      on_step(step)
  return PhaseResult(state, setup, time.perf_counter() - t0,
                     losses_sum / count if count else float("nan"))


# ------------------------------------------------------------------------- checkpoints


def save_state(directory, state, setup: LightSetup, meta):
  """Writes `state` with `meta` (+ capacity and render budget) as one atomic checkpoint."""
  meta = dict(meta, step=int(state.step), capacity=int(state.model.capacity),
              max_intersections=int(setup.step_config.settings.max_intersections))
  return ckpt.save_checkpoint(directory, state, meta, keep=1)


def restore_state(directory, config, setup: LightSetup, bounds):
  """(state, setup with the saved budget, meta) of the newest checkpoint, or None."""
  paths = ckpt.list_checkpoints(directory)
  if not paths:
    return None
  meta = ckpt.read_meta(paths[-1])
  template = densify_lib.grow_capacity(init_state(config, setup, bounds), meta["capacity"])
  state, meta = ckpt.restore_checkpoint(paths[-1], template)
  settings = setup.step_config.settings.holding_budget(meta["max_intersections"])
  setup = setup._replace(step_config=dataclasses.replace(setup.step_config, settings=settings))
  return state, setup, meta
