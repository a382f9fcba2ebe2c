"""Training a relightable field on (view, light) captures: its setup and phases.

The cameras are fixed and the lights grow. The step and the loop are the colour field's
(`mfsample.train.step.train_step`, `mfsample.train.loop.run_steps`) with the relightable
field as their `Field` (`field.RelightableField`): each step draws one (view, light) pair,
renders M samples theta(z) of the field under that light into that view and takes the
gradient of the paper's Eq. 9 loss on the linear radiance, then Adam with per-group learning
rates, B_hat clamped into its bounds, and the 3DGS densification statistics accumulated;
the host densifies on schedule, and an overflowing render grows the budget and reruns the
step. The step's settings are a `TrainSettings` whose background is black; its SH schedule is
unused.

Pairs are drawn in epochs of random permutations of the current (view, light) pairs, seeded
by (seed, phase start, epoch): every pair is seen equally often, and every strategy of a
planning run sees the same sequence of (view, light slot) pairs. Images of all lights live in
one array [L_max, V, H, W, 3] padded to the protocol's number of lights, so one compilation
serves every phase and every strategy. Checkpoints are the colour field's
(`mfsample.train.checkpoint`), restored with its fallback to an older intact one.
"""

import dataclasses
import time
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from mfsample import settings_checks as sc
from mfsample.lighting import field
from mfsample.samplers import SamplerSpec
from mfsample.train import checkpoint as ckpt
from mfsample.train.initial import model_key
from mfsample.train.loop import (
    TrainSetup,
    checkpoint_meta,
    init_state,
    make_setup,
    restore_latest,
    run_steps,
    step_rows,
)
from mfsample.train.settings import TrainSettings
from mfsample.train.step import TrainState


@dataclasses.dataclass(frozen=True)
class FieldSettings:
  """The relightable field a run starts from.

  Attributes:
    out_coeffs: m, outgoing SH coefficients of T (1: diffuse; 4, 9, 16).
    light_coeffs: n, SH coefficients of a light (4, 9 or 16).
    init_points: random initial points in the scene box (no SfM).
    init_opacity: initial opacity of every Gaussian.
  """

  out_coeffs: int = 4
  light_coeffs: int = 16
  init_points: int = 3_000
  init_opacity: float = 0.1

  def __post_init__(self):
    sc.check_choice("FieldSettings.out_coeffs", self.out_coeffs, field.COEFFICIENT_COUNTS)
    sc.check_choice("FieldSettings.light_coeffs", self.light_coeffs,
                    field.COEFFICIENT_COUNTS[1:])
    sc.check_int("FieldSettings.init_points", self.init_points, minimum=1)
    sc.check_float("FieldSettings.init_opacity", self.init_opacity, above=0.0, below=1.0)

  @property
  def group_shapes(self):
    return field.group_shapes(self.out_coeffs, self.light_coeffs)


class LightRecipe(NamedTuple):
  """A relightable field to train: its training, its start and its sampler, typed.

  Attributes:
    settings: `TrainSettings` of the whole run (`num_steps`: every phase; its loss's
      `volume_weight` set, its background black).
    field: `FieldSettings`.
    spec: the model's `SamplerSpec`.
    extent: the scene extent (world units).
  """

  settings: TrainSettings
  field: FieldSettings
  spec: SamplerSpec
  extent: float


def make_light_setup(recipe: LightRecipe, model, seed) -> TrainSetup:
  """`TrainSetup` of the relightable `model` (its step-0 state; lambda is the settings')."""
  return make_setup(recipe.settings, model, seed=seed, extent=recipe.extent, num_views=1,
                    field=field.RelightableField(recipe.field.out_coeffs,
                                                 recipe.field.light_coeffs))


def initial_model(recipe: LightRecipe, seed, bounds):
  """The step-0 relightable model: `init_points` random points in the box `bounds`, T = 0."""
  f = recipe.field
  rng = np.random.default_rng([int(seed), 0])
  low, high = (np.asarray(b, np.float64) for b in bounds)
  points = rng.uniform(low, high, (f.init_points, 3))
  return field.init_relightable(model_key(seed), points, spec=recipe.spec,
                                out_coeffs=f.out_coeffs, light_coeffs=f.light_coeffs,
                                init_scales=recipe.settings.b_hat_init_scales(recipe.extent),
                                init_opacity=f.init_opacity)


def initial_state(recipe: LightRecipe, setup: TrainSetup, bounds) -> TrainState:
  """The step-0 `TrainState` (`initial_model`, the step keys of the seed)."""
  return init_state(initial_model(recipe, setup.seed, bounds), setup)


def start(recipe: LightRecipe, seed, bounds):
  """(`TrainSetup`, step-0 `TrainState`) of a run."""
  model = initial_model(recipe, seed, bounds)
  setup = make_light_setup(recipe, model, seed)
  return setup, init_state(model, setup)


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


def train_steps(setup: TrainSetup, state, images, lights, cameras, *, num_lights,
                phase_start, end, max_traces=None, on_step=None) -> PhaseResult:
  """Trains from `state.step` to `end` on the first `num_lights` light slots.

  Args:
    setup: `TrainSetup` of the relightable field (`make_light_setup`).
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

  def pick(step):  # one (light slot, view) pair per step, and its Sobol rows
    light, view = pair_for_step(setup.seed, step, phase_start, num_views, num_lights)
    return (jnp.asarray([light], jnp.int32), jnp.asarray([view], jnp.int32)), step_rows(
        setup, step)

  losses_sum, count = 0.0, 0
  t0 = time.perf_counter()
  for done in run_steps(setup, state, (images, lights, cameras), pick=pick, end=end,
                        max_traces=max_traces):
    state, setup = done.state, done.setup
    losses_sum += float(done.metrics.data_loss)
    count += 1
    if on_step is not None:
      on_step(int(state.step))
  return PhaseResult(state, setup, time.perf_counter() - t0,
                     losses_sum / count if count else float("nan"))


def fit_relightable(model, images, lights, cameras, settings: TrainSettings, *, key,
                    extent=None):
  """Trains a relightable field on captures of fixed cameras under several lights.

  Each step renders a sample theta(z) of the field under one light into one view (the
  pairs in epochs of random permutations) and takes an Adam step on the paper's Eq. 9 on
  linear radiance, as `mfsample.train.fit` does for a colour field (same settings, same
  budgets; the background is `settings.background`, black for the oracle's captures).

  Args:
    model: the step-0 relightable `Model` (`field.init_relightable`).
    images: [L, V, H, W, 3] captures of the V cameras under each of the L lights (linear
      radiance; `captures.capture_many`).
    lights: [L, n] the lights.
    cameras: `Camera` [V].
    settings: `TrainSettings` (`loss.volume_weight` None: 1 / (L V)).
    key: a JAX PRNG key (the pair order, the step keys, densification).
    extent: scene extent (default: `settings.extent`, else from the cameras).

  Returns:
    (the trained `Model`, history: a dict every `settings.log_every` steps).
  """
  import jax

  from mfsample import arg_checks
  from mfsample.data.datasets import scene_extent

  arg_checks.check_key(key)
  m, n = field.coefficient_counts(model)
  lights = np.asarray(lights, np.float32)
  arg_checks.check_shape("lights", lights, (None, n), "one light of n coefficients per row")
  images = jnp.asarray(images, jnp.float32)
  num_lights, num_views = lights.shape[0], cameras.batch_shape[0]
  arg_checks.check_shape("images", images, (num_lights, num_views, cameras.height,
                                            cameras.width, 3))
  seed = int(jax.random.randint(key, (), 0, np.iinfo(np.int32).max))
  if extent is None:
    extent = settings.extent if settings.extent is not None else scene_extent(cameras)
  setup = make_setup(settings, model, seed=seed, extent=extent,
                     num_views=num_lights * num_views, field=field.RelightableField(m, n))
  state, history = init_state(model, setup), []

  def pick(step):
    light, view = pair_for_step(seed, step, 0, num_views, num_lights)
    return (jnp.asarray([light], jnp.int32), jnp.asarray([view], jnp.int32)), step_rows(
        setup, step)

  data = (images, jnp.asarray(lights), jax.tree.map(jnp.asarray, cameras))
  for done in run_steps(setup, state, data, pick=pick, end=settings.num_steps):
    state = done.state
    step = int(state.step)
    if step % settings.log_every == 0 or step == settings.num_steps:
      history.append({"step": step, "loss": float(done.metrics.loss),
                      "data_loss": float(done.metrics.data_loss),
                      "volume": float(done.metrics.volume), "live": state.model.num_live})
  return state.model, history


# ------------------------------------------------------------------------- checkpoints


def save_state(directory, state, setup: TrainSetup, meta):
  """Writes `state` with `meta` (+ step, capacity and render budget) as one atomic
  checkpoint."""
  return ckpt.save_checkpoint(directory, state, checkpoint_meta(state, setup, **meta), keep=1)


def restore_state(directory, recipe: LightRecipe, setup: TrainSetup, bounds):
  """(state, setup with the saved budget, meta) of the newest intact checkpoint, or None.

  Raises:
    ckpt.CorruptCheckpointError: checkpoints exist but none can be read (the protocol then
      trains the phase again).
  """
  return restore_latest(directory, setup, lambda: initial_state(recipe, setup, bounds))
