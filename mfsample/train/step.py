"""The training state and the jitted training step (static shapes, no host logic).

One step: draw z, render M samples theta(z) of the model into each of its training targets,
take the gradient of the Eq. 9 loss w.r.t. the mean and B_hat, apply Adam with per-group learning
rates, clamp B_hat into its bounds, and accumulate the densification statistics. If any
render overflowed its intersection budget the step returns the *unchanged* state and
raises `overflow`: the host grows the budget and re-runs the step, so training never
updates on a truncated image.

What differs between kinds of field is a small static interface, `Field`: which image,
camera (and light) a step trains on, how a sample of the model is rendered there, and the
per-step schedule of the model (3DGS's rising SH degree). `ColourField` is the 3DGS colour
field (SH colour per Gaussian); the relightable field of `mfsample.lighting` is the other.

Every step trains on a batch of B = `StepConfig.batch_size` >= 1 targets (views, or
(light, view) pairs), split over `StepConfig.num_devices` devices
(`mfsample.sharding.reduce_sharded`), each with its own z. Precisely, the B targets at the
positions p = tB .. tB + B - 1 of the target order (a B = 1 run's steps tB .. tB + B - 1,
each with that step's z: Sobol rows p M .. p M + M - 1, or the key fold_in(key, p)) are all
evaluated at the step's parameters, and

  loss = (1/B) sum_b D_b - lambda_t ||B_hat||_1,   D_b = (1/M) sum_m L1-D-SSIM(theta(z_bm), b),

the mean over the batch of each target's Eq. 9 data term (itself the mean over its M
samples), less the volume term of the step. Its gradient (the mean of the per-target
gradients, plus the volume term's) drives one Adam step. The densification statistics are
accumulated as if the B targets had been B consecutive steps at the same parameters: each
target adds its own NDC gradient norm ||dD_b / d(2D centre)|| (of its own data term, not of
the batch mean, so 3DGS's threshold keeps its meaning) and one visibility count for every
Gaussian it sees, and the largest screen radius is the largest over the targets. Counts and
radii are exact; the gradient norms are summed in another order than B consecutive steps
would (float rounding). A step overflows if any target's render does. Schedules (learning
rates, densification, the volume term, `stochastic_until`, the SH degree) count steps, so a
run of `num_steps` steps sees B times as many targets as with B = 1. B = 1 is the plain
single-target step, with no code path of its own: `sharding.reduce_sharded` calls a batch of
one element directly.
"""

import dataclasses
import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import optax

from mfsample import samplers, sharding
from mfsample.model import Model, sample
from mfsample.renderer.render import render
from mfsample.renderer.settings import RenderSettings
from mfsample.samplers import clamp_b_hat
from mfsample.train import losses, optim


class DensifyStats(NamedTuple):
  """Per-Gaussian statistics between two densifications (3DGS).

  Attributes:
    grad_accum: [C] sum over steps of ||dL/d(2D centre)|| in NDC units (pixel gradient
      times half the image size, as 3DGS measures it, so the threshold 2e-4 carries over
      across resolutions).
    count: [C] int32 number of steps in which the Gaussian was visible.
    max_radii: [C] largest screen radius seen (pixels).
  """

  grad_accum: chex.Array
  count: chex.Array
  max_radii: chex.Array

  @classmethod
  def zeros(cls, capacity, dtype=jnp.float32):
    return cls(jnp.zeros((capacity,), dtype), jnp.zeros((capacity,), jnp.int32),
               jnp.zeros((capacity,), dtype))


class TrainState(NamedTuple):
  """Everything the jitted step reads and writes.

  Attributes:
    step: int32 scalar, completed steps.
    model: `Model` (mean, B_hat, signs, mask, active SH degree).
    opt_state: state of `optim.make_optimizer`.
    stats: `DensifyStats`.
    key: [2] uint32 PRNG key; the key of the target at position p of the target order is
      fold_in(key, p), so a resumed run draws the same numbers.
  """

  step: chex.Array
  model: Model
  opt_state: optax.OptState
  stats: DensifyStats
  key: chex.Array


class StepMetrics(NamedTuple):
  """Scalars a step reports (host reads them every step, cheaply)."""

  loss: chex.Array  # total loss (Eq. 9): the batch's mean data term less the volume term
  data_loss: chex.Array  # photometric term, mean over the targets and their samples
  volume: chex.Array  # ||B_hat||_1 over live Gaussians
  overflow: chex.Array  # bool: a render exceeded the budget; the state was not updated
  num_padded: chex.Array  # int32: largest padded intersection count over the renders


@dataclasses.dataclass(frozen=True)
class StepConfig:
  """Static (hashable) settings of the step, resolved for one run (`loop.make_setup`).

  Attributes:
    settings: `RenderSettings` (its budget is grown by the host on overflow).
    background: RGB tuple behind the Gaussians.
    num_samples: M, samples rendered per target (paper: 1).
    ssim_weight: w of the D-SSIM term (3DGS: 0.2).
    volume_weight: lambda of Eq. 9.
    volume_every: the volume term is applied on every `volume_every`-th step only.
    volume_until: no volume term from this step on (authors: the last 100 steps).
    stats_until: densification statistics are accumulated before this step.
    sh_degree_every: the active SH degree rises by one every this many steps (3DGS: 1000);
      0: every band from the first step (a model trained elsewhere).
    stochastic_until: from this step on the step renders the mean (z = 0), while the
      volume term goes on as configured. The paper samples at every step (the default,
      never); the authors' code stops after the first opacity reset (step 3000).
    rates: `optim.LearningRates` of the per-group Adam, in world units.
    train_mean: False freezes the mean: its gradient is stopped, so Adam's moments of it stay
      zero and its update is exactly zero; only B_hat is fitted (post-hoc uncertainty of a
      pretrained model, `mfsample.train.posthoc`).
    batch_size: B, targets per step (module docstring); 1: the single-target step.
    num_devices: devices the B targets are split over (the devices of every process,
      `mfsample.sharding.mesh_devices`).
  """

  settings: RenderSettings = RenderSettings()
  background: tuple = (0.0, 0.0, 0.0)
  num_samples: int = 1
  ssim_weight: float = 0.2
  volume_weight: float = 0.0
  volume_every: int = 10
  volume_until: int = 2**31 - 1
  stats_until: int = 2**31 - 1
  sh_degree_every: int = 1000
  stochastic_until: int = 2**31 - 1
  rates: optim.LearningRates = optim.LearningRates()
  train_mean: bool = True
  batch_size: int = 1
  num_devices: int = 1

  @property
  def optimizer(self):
    return optim.make_optimizer(self.rates)

  def with_settings(self, settings: RenderSettings):
    """The same step with other render settings (a grown budget)."""
    return dataclasses.replace(self, settings=settings)


@dataclasses.dataclass(frozen=True)
class ColourField:
  """A field with SH colour per Gaussian (3DGS): the step's `Field`.

  Training data: (images [V, H, W, 3], `Camera` [V]); a target: a view index (int32).
  The active SH degree rises by one every `StepConfig.sh_degree_every` steps (all bands from
  the first step when it is 0).

  Every `Field` is a frozen (hashable) dataclass, a static argument of the jitted step, with
  these three methods.
  """

  def prepare(self, model, step, cfg: "StepConfig"):
    """The model as the step sees it (its active SH degree at `step`)."""
    max_degree = model.max_sh_degree
    if cfg.sh_degree_every > 0:
      degree = jnp.minimum(step // cfg.sh_degree_every, max_degree)
    else:
      degree = jnp.asarray(max_degree)
    return model.replace(sh_degree=degree.astype(jnp.int32))

  def target(self, data, index):
    """(image [H, W, 3], camera, extra) of the target: the view `index`."""
    images, cameras = data
    return images[index], cameras[index], None

  def render(self, model, z, camera, extra, cfg: "StepConfig", screen_offset):
    """`RenderOutput` of the sample theta(z) of `model` seen by `camera`."""
    del extra
    return render(sample(model, z), camera, background=cfg.background,
                  settings=cfg.settings, screen_offset=screen_offset)


COLOUR = ColourField()


def init_train_state(model: Model, cfg: StepConfig, key):
  """A fresh `TrainState` (step 0) for `model`."""
  return TrainState(step=jnp.int32(0), model=model, opt_state=cfg.optimizer.init(model.params),
                    stats=DensifyStats.zeros(model.capacity), key=jnp.asarray(key))


def _mask_rows(tree, mask):
  """Zeros every [C, ...] leaf on rows where mask is False."""
  def f(x):
    return jnp.where(mask.reshape((-1,) + (1,) * (x.ndim - 1)), x, jnp.zeros_like(x))
  return jax.tree.map(f, tree)


def step_z(cfg, model, key, position, step, rows):
  """z `[M, *z_shape]` of the target at `position` of the target order, in step `step`.

  The target's Sobol rows where the spec's z source is Sobol, else fresh uniforms from
  `fold_in(key, position)` (`samplers.draw_z`); zero from `stochastic_until` on (the mean
  is rendered).
  """
  z = samplers.draw_z(model, cfg.num_samples, jax.random.fold_in(key, position), rows)
  return jnp.where(step < cfg.stochastic_until, z, 0.0)


def volume_weight_at(cfg, step):
  """The weight of Eq. 9's volume term in `step`: lambda on every `volume_every`-th step
  before `volume_until`, else 0."""
  volume_on = ((step + 1) % cfg.volume_every == 0) & (step < cfg.volume_until)
  return jnp.where(volume_on, cfg.volume_weight, 0.0)


def _trainable(params, cfg):
  """`params` with the mean's gradient stopped unless `cfg.train_mean`."""
  if not cfg.train_mean:
    params = params._replace(mean=jax.lax.stop_gradient(params.mean))
  return params


def _volume(m, dtype):
  """||B_hat||_1 of a stochastic model; 0 for a deterministic one."""
  return losses.volume(m) if m.spec.stochastic else jnp.zeros((), dtype)


def _data_term(field, m, z, image, camera, extra, cfg, offset2d):
  """(D, aux): Eq. 9's data term of one target, the mean over its M samples z [M, k] of the
  photometric loss, and the samples' (radii [M, C], visible [M, C], `TileStats` [M])."""
  def one(z_i):
    out = field.render(m, z_i, camera, extra, cfg, offset2d)
    return losses.photometric(out.rgb, image, cfg.ssim_weight), (out.radii, out.visible,
                                                                  out.stats)

  if cfg.num_samples == 1:
    # A plain call keeps the renderer's cheap skipping of unused budget (vmap would not).
    data_loss, aux = jax.tree.map(lambda x: x[None], one(z[0]))
  else:
    data_loss, aux = jax.lax.map(one, z)  # sequential: same reason, and bounded memory
  return jnp.mean(data_loss), aux


def _ndc_grad_norm(grad2d, camera):
  """[C] ||dL/d(2D centre)|| in NDC units (3DGS): pixel gradient times half the image size."""
  half_size = jnp.array([0.5 * camera.width, 0.5 * camera.height], grad2d.dtype)
  return jnp.linalg.norm(grad2d * half_size, axis=-1)


def _target_terms(target, model, data, step, cfg, field):
  """One target's share of a step: (sums, maxes) for `sharding.reduce_sharded`.

  sums: (D, dD/dparams, [C] NDC gradient norm where seen, [C] int32 seen);
  maxes: ([C] largest screen radius where seen (0 elsewhere), int32 overflow, int32 padded
  intersections).
  """
  index, z = target
  image, camera, extra = field.target(data, index)
  offset2d = jnp.zeros((model.capacity, 2), model.params.mean["means"].dtype)

  def data_fn(params, offset2d):
    m = model.replace(params=_trainable(params, cfg))
    return _data_term(field, m, z, image, camera, extra, cfg, offset2d)

  grad_fn = jax.value_and_grad(data_fn, argnums=(0, 1), has_aux=True)
  (data_loss, (radii, visible, stats)), (grads, grad2d) = grad_fn(model.params, offset2d)
  seen = jnp.any(visible, axis=0) & (step < cfg.stats_until)
  sums = (data_loss, grads, jnp.where(seen, _ndc_grad_norm(grad2d, camera), 0.0),
          seen.astype(jnp.int32))
  maxes = (jnp.where(seen, jnp.max(radii, axis=0), 0), jnp.any(stats.overflow).astype(jnp.int32),
           jnp.max(stats.num_padded))
  return sums, maxes


class BatchGradients(NamedTuple):
  """What a batch of B targets gives at the step's parameters (module docstring).

  Attributes:
    loss: (1/B) sum_b D_b - lambda_t ||B_hat||_1.
    data_loss: (1/B) sum_b D_b.
    volume: ||B_hat||_1 over live Gaussians (0 for a deterministic model).
    grads: d loss / d params (the mean of the per-target gradients plus the volume term's).
    stats: `DensifyStats` of the batch alone: grad_accum [C] the sum over the targets of
      ||dD_b / d(2D centre)|| (NDC) where seen, count [C] the targets that see each
      Gaussian, max_radii [C] the largest radius over them (0 where none sees it).
    overflow: bool, a target's render overflowed.
    num_padded: int32, the largest padded intersection count over the targets.
  """

  loss: chex.Array
  data_loss: chex.Array
  volume: chex.Array
  grads: object
  stats: DensifyStats
  overflow: chex.Array
  num_padded: chex.Array


def batch_gradients(state: TrainState, data, index, rows, *, cfg: StepConfig,
                    field=COLOUR) -> BatchGradients:
  """`BatchGradients` of the B targets `index` (leaves [B]) with Sobol rows [B, M, k],
  split over `cfg.num_devices` devices; inside jit."""
  step = state.step
  model = field.prepare(state.model, step, cfg)
  b = jax.tree.leaves(index)[0].shape[0]
  positions = step * b + jnp.arange(b)
  z = jax.vmap(lambda p, r: step_z(cfg, model, state.key, p, step, r))(
      positions, jnp.asarray(rows))
  (data_sum, grad_sum, grad_norms, counts), (radii, overflow, num_padded) = (
      sharding.reduce_sharded(
          lambda target, mdl, dat: _target_terms(target, mdl, dat, step, cfg, field),
          (index, z), model, data, num_devices=cfg.num_devices))
  data_loss = data_sum / b
  volume_weight = volume_weight_at(cfg, step)

  def volume_fn(params):
    volume = _volume(model.replace(params=_trainable(params, cfg)), data_loss.dtype)
    return -volume_weight * volume, volume

  (_, volume), volume_grads = jax.value_and_grad(volume_fn, has_aux=True)(model.params)
  grads = jax.tree.map(lambda g, v: g / b + v, grad_sum, volume_grads)
  stats = DensifyStats(grad_norms, counts, radii.astype(state.stats.max_radii.dtype))
  return BatchGradients(data_loss - volume_weight * volume, data_loss, volume, grads, stats,
                        overflow > 0, num_padded)


def train_step(state: TrainState, data, index, rows, *, cfg: StepConfig, field=COLOUR):
  """One optimisation step on a batch of B = `cfg.batch_size` targets (pure; jittable).

  Renders M samples theta(z) for every target, takes the gradient of Eq. 9 (the mean of
  the targets' data terms less the volume term), applies Adam with the per-group rates,
  freezes padding rows, clamps B_hat into its bounds and accumulates the densification
  statistics. If any render overflowed its budget, the step returns the *unchanged* state
  and `overflow`: grow the budget (`loop.with_grown_budget`) and run it again.

  Args:
    state: `TrainState`.
    data: the field's training data (`ColourField`: images [V, H, W, 3] and `Camera` [V]).
    index: [B] the targets in `data` (`ColourField`: view indices, int32; every leaf [B]).
    rows: [B, M, k] the targets' Sobol z rows (the spec's z source is Sobol), or [B, M, 0]
      (uniform z from the state's key); `loop.step_targets` gives both.
    cfg: `StepConfig` (static).
    field: the `Field` (static): what a step trains on and how a sample is rendered.

  Returns:
    (new state, `StepMetrics`).
  """
  model = field.prepare(state.model, state.step, cfg)
  g = batch_gradients(state, data, index, rows, cfg=cfg, field=field)
  new_stats = DensifyStats(grad_accum=state.stats.grad_accum + g.stats.grad_accum,
                           count=state.stats.count + g.stats.count,
                           max_radii=jnp.maximum(state.stats.max_radii, g.stats.max_radii))
  updates, opt_state = cfg.optimizer.update(g.grads, state.opt_state, model.params)
  updates = _mask_rows(updates, model.mask)  # padding rows never move
  params = optax.apply_updates(model.params, updates)
  params = params._replace(b_hat=clamp_b_hat(params.b_hat, model.spec))
  new_model = model.replace(params=params)
  new_state = TrainState(state.step + 1, new_model, opt_state, new_stats, state.key)

  # On overflow the step is void: keep the old state. A select fuses into the elementwise
  # updates (a lax.cond would copy the whole state); the shape check, at trace time, keeps
  # it from silently broadcasting a malformed state.
  chex.assert_trees_all_equal_shapes_and_dtypes(state, new_state)
  new_state = jax.tree.map(lambda old, new: jnp.where(g.overflow, old, new), state, new_state)
  metrics = StepMetrics(loss=g.loss, data_loss=g.data_loss, volume=g.volume,
                        overflow=g.overflow, num_padded=g.num_padded)
  return new_state, metrics


# Jitted with the (hashable) step config and field static: runs with equal configs share
# compilations.
train_step_jit = jax.jit(train_step, static_argnames=("cfg", "field"))


def clear_compiled_steps():
  """Drops every compiled training step (`train_step_jit`'s cache), and nothing else.

  Each model that densifies compiles the step anew for every capacity bucket and view count
  it passes through, and XLA:CPU keeps each executable's code mapped in memory: over the
  densified models of a long study the mappings exhaust the process's limit
  (vm.max_map_count, 65530 on Linux; seen in the lego study's second seed). A caller that
  trains many such models clears the steps between them; the next model recompiles the few
  shapes it needs, seconds against its minutes of training.
  """
  train_step_jit.clear_cache()


def make_train_step(cfg: StepConfig, field=COLOUR, max_traces=None):
  """`fn(state, data, index, rows) -> (state, StepMetrics)`, jitted.

  Args:
    cfg: `StepConfig`.
    field: the `Field` (default: `COLOUR`).
    max_traces: if set, a separately jitted step wrapped in `chex.assert_max_traces`
      (tests use it to show that the step does not retrace); otherwise `train_step_jit`.
  """
  if max_traces is None:
    return functools.partial(train_step_jit, cfg=cfg, field=field)
  counted = chex.assert_max_traces(train_step, n=max_traces)
  return functools.partial(jax.jit(counted, static_argnames=("cfg", "field")), cfg=cfg,
                           field=field)
