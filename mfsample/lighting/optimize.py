"""Gradient ascent of U over lights on the sphere |xi| = norm (the paper's light optimiser).

The paper maximises U w.r.t. xi with Adam from the one-hot light of highest U; the authors'
light optimiser is unpublished, so its numbers are ours (`AscentSettings`). U(c xi) =
c^2 U(xi) grows without bound along any ray, so the ascent stays on the sphere |xi| = norm:
the gradient's radial part (which only rescales xi, and would dominate Adam's per-coordinate
normalisation: it is 2 U / |xi| against a tangent part that vanishes at the optimum) is
removed before Adam, and every step is projected back onto the sphere,
xi <- norm (xi + update) / |xi + update| (Riemannian gradient, retraction). The rate decays
along a cosine from `lr` to `final_lr`, so the iterate settles rather than circling the
optimum at a distance set by the rate.

The gradient is the renderer's: U(xi) is rendered under xi (`uncertainty.light_uncertainty`)
and differentiated. The whole ascent is one `lax.scan`; if any render overflowed its budget,
the ascent is repeated with a larger one.
"""

import dataclasses
import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax

from mfsample import settings_checks as sc
from mfsample.lighting import lights as lights_lib
from mfsample.lighting import uncertainty as lu
from mfsample.renderer.budget import BudgetExceededError
from mfsample.renderer.settings import RenderSettings
from mfsample.sharding import default_num_devices
from mfsample.view_uncertainty import check_inputs


@dataclasses.dataclass(frozen=True)
class AscentSettings:
  """Static settings of the light ascent (unpublished by the authors; these are ours).

  Attributes:
    steps: Adam steps.
    lr: Adam learning rate at the first step (b1, b2, eps: Adam's defaults, as the paper).
    final_lr: the rate at the last step (cosine decay from `lr`).
    norm: the sphere `|xi| = norm` the iterate stays on.
  """

  steps: int = 100
  lr: float = 0.05
  final_lr: float = 0.005
  norm: float = lights_lib.UNIFORM_NORM

  def __post_init__(self):
    sc.check_int("AscentSettings.steps", self.steps, minimum=1)
    sc.check_float("AscentSettings.lr", self.lr, above=0.0)
    sc.check_float("AscentSettings.final_lr", self.final_lr, above=0.0, maximum=self.lr)
    sc.check_float("AscentSettings.norm", self.norm, above=0.0)


class AscentResult(NamedTuple):
  """What `ascend` returns.

  Attributes:
    light: [n] the final light (`|light| = norm`).
    value: U(light).
    values: [steps] U at the start of every step.
    trajectory: [steps + 1, n] the light before every step and after the last.
    settings: `RenderSettings` that sufficed.
  """

  light: np.ndarray
  value: float
  values: np.ndarray
  trajectory: np.ndarray
  settings: RenderSettings


@functools.partial(jax.jit, static_argnames=("settings", "opt", "num_devices"))
def _ascend(model, cameras, z, xi0, *, settings, opt, num_devices):
  schedule = optax.cosine_decay_schedule(opt.lr, opt.steps, alpha=opt.final_lr / opt.lr)
  tx = optax.adam(schedule)

  def u(xi):
    out = lu._light_uncertainty(model, cameras, z, xi, settings=settings,
                                num_devices=num_devices)
    return out.value, (jnp.max(out.stats.num_padded), jnp.any(out.stats.overflow))

  def project(xi):
    return xi * (opt.norm / jnp.linalg.norm(xi))

  def body(carry, _):
    xi, state = carry
    (value, (need, over)), grad = jax.value_and_grad(u, has_aux=True)(xi)
    unit = xi / jnp.linalg.norm(xi)
    grad = grad - jnp.dot(grad, unit) * unit  # the sphere's tangent part: no radial push
    updates, state = tx.update(-grad, state, xi)  # ascent: descend on -U
    return (project(xi + updates), state), (value, xi, need, over)

  xi0 = project(xi0)
  (xi, _), (values, trajectory, needs, overs) = jax.lax.scan(
      body, (xi0, tx.init(xi0)), None, length=opt.steps)
  value, (need, over) = u(xi)
  trajectory = jnp.concatenate([trajectory, xi[None]], axis=0)
  return (xi, value, values, trajectory, jnp.maximum(jnp.max(needs), need),
          jnp.any(overs) | over)


def ascend(model, cameras, z, xi0, *, opt: AscentSettings, settings: RenderSettings,
           max_budget=1 << 24) -> AscentResult:
  """Projected Adam on U(xi) from `xi0` over `cameras` (module docstring).

  Args:
    model: a relightable `Model`.
    cameras: `Camera` [B] over which U is summed.
    z: `[M, *z_shape]` samples (the same at every step, as the camera optimisation).
    xi0: [n] start (scaled onto the sphere first).
    opt: `AscentSettings`.
    settings: starting `RenderSettings`.
    max_budget: refuse to grow the budget beyond this.

  Returns:
    `AscentResult`.
  """
  _, n = lu._check_model(model)
  lu.check_cameras(cameras)
  check_inputs(model, z, sync=True)  # called once, it syncs anyway
  xi0 = lights_lib.on_sphere(lights_lib.check_light(xi0, n, "xi0"), opt.norm)
  dtype = model.params.mean["means"].dtype
  num_devices = default_num_devices(cameras.batch_shape[0])
  while True:
    xi, value, values, trajectory, need, overflow = _ascend(
        model, cameras, z, jnp.asarray(xi0, dtype), settings=settings, opt=opt,
        num_devices=num_devices)
    if not bool(overflow):
      break
    need = int(need)
    # At least double: an overflowing render may under-report what it needed.
    grown = settings.holding_budget(max(1 << max(need - 1, 0).bit_length(),
                                        2 * settings.max_intersections))
    if grown.max_intersections > max_budget:
      raise BudgetExceededError(f"light ascent needs {need} intersections, more than "
                                f"max_budget={max_budget}")
    settings = grown
  chex.assert_tree_all_finite((xi, value))
  return AscentResult(np.asarray(xi, np.float64), float(value), np.asarray(values),
                      np.asarray(trajectory), settings)
