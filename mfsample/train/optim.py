"""Adam with per-group learning rates (3DGS), as one optax transformation.

Adam's update is per entry, so per-group learning rates are a per-leaf scale after
`optax.scale_by_adam`. Keeping a single Adam state whose moments `mu`, `nu` mirror the
parameter tree makes densification simple and obviously aligned: whatever row operation
is applied to the parameters is applied to `mu` and `nu` (`map_moments`).

Learning rates (3DGS, Kerbl et al. 2023; B_hat: the authors' code):
centres 1.6e-4 x extent decaying exponentially to 1.6e-6 x extent over `max_steps`, SH DC
2.5e-3, SH rest 2.5e-3 / 20, opacity 0.05, log-scale 5e-3, quaternion 1e-3; B_hat entries
of centres 1.6e-5 x extent (constant), opacity 5e-3, log-scale 5e-4, quaternion 1e-4,
DC 2.5e-3, rest 1.25e-4.
"""

import dataclasses
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax

from mfsample.train.settings import OptimSettings


def exponential_lr(init, final, max_steps):
  """3DGS position schedule: log-linear from `init` (step 0) to `final` (max_steps on)."""
  if init <= 0 or final <= 0:
    raise ValueError(f"learning rates must be > 0, got {init}, {final}")
  log_init, log_final = float(np.log(init)), float(np.log(final))
  max_steps = max(int(max_steps), 1)

  def schedule(count):
    t = jnp.clip(jnp.asarray(count, jnp.float32) / max_steps, 0.0, 1.0)
    return jnp.exp(log_init * (1.0 - t) + log_final * t)

  return schedule


@dataclasses.dataclass(frozen=True)
class LearningRates:
  """Per-group learning rates (hashable, so a jitted step can take them as static).

  Attributes:
    position: (init, final, max_steps) of the exponential decay of the mean's centres
      (already multiplied by the scene extent).
    mean: ((group, lr), ...) for the other mean groups.
    b_hat: ((group, lr), ...) for B_hat's raw entries (the centres' already times extent).
  """

  position: tuple = (1.6e-4, 1.6e-6, 30_000)
  mean: tuple = ()
  b_hat: tuple = ()

  def rate(self, kind, group):
    """A float or a schedule `count -> lr` for the leaf `params.<kind>[group]`."""
    if kind == "mean" and group == "means":
      return exponential_lr(*self.position)
    table = dict(self.mean if kind == "mean" else self.b_hat)
    if group not in table:
      raise KeyError(f"no learning rate for {kind} group {group!r}")
    return table[group]


class ScaleByGroupLRState(NamedTuple):
  count: chex.Array  # int32 scalar, steps taken (drives the schedules)


def scale_by_group_lr(rates: LearningRates) -> optax.GradientTransformation:
  """Multiplies the leaf `params.<kind>[group]` by -rates.rate(kind, group).

  The rate is looked up from the leaf's path, so the transformation works for any set of
  groups (a relightable model adds one) without knowing the parameter tree in advance.
  """

  def init(params):
    del params
    return ScaleByGroupLRState(count=jnp.zeros([], jnp.int32))

  def update(updates, state, params=None):
    del params

    def scale(path, u):
      kind, group = _kind_and_group(path)
      rate = rates.rate(kind, group)
      rate = rate(state.count) if callable(rate) else rate
      return -jnp.asarray(rate, u.dtype) * u

    out = jax.tree_util.tree_map_with_path(scale, updates)
    return out, ScaleByGroupLRState(count=optax.safe_increment(state.count))

  return optax.GradientTransformation(init, update)


def _kind_and_group(path):
  """("mean" | "b_hat", group) of a leaf path in a `Params` tree."""
  names = [getattr(k, "name", None) or getattr(k, "key", None) for k in path]
  if len(names) < 2 or names[0] not in ("mean", "b_hat"):
    raise ValueError(f"not a Params leaf: {jax.tree_util.keystr(path)}")
  return names[0], names[1]


def learning_rates(optim: OptimSettings, extent, max_steps, groups) -> LearningRates:
  """`LearningRates` of a model with parameter `groups`, in world units.

  Args:
    optim: `OptimSettings`.
    extent: scene extent (world units): the centres' rates (mean and B_hat) scale with it.
    max_steps: steps of the centres' decay.
    groups: the model's groups (each must have a rate in `optim`).
  """
  mean, b_hat = dict(optim.mean_lr), dict(optim.b_hat_lr)
  missing = [g for g in groups if g != "means" and g not in mean]
  if missing:
    raise ValueError(f"OptimSettings.mean_lr has no learning rate for the model's groups "
                     f"{missing}")
  return LearningRates(
      position=(float(optim.position_lr_init) * extent,
                float(optim.position_lr_final) * extent, int(max_steps)),
      mean=tuple((g, mean[g]) for g in groups if g != "means"),
      b_hat=tuple((g, b_hat[g] * (extent if g == "means" else 1.0)) for g in groups
                  if g in b_hat),
  )


def make_optimizer(rates: LearningRates, b1=0.9, b2=0.999,
                   eps=1e-15) -> optax.GradientTransformation:
  """Adam (3DGS: eps 1e-15) with the per-group learning rates `rates`."""
  return optax.chain(optax.scale_by_adam(b1=b1, b2=b2, eps=eps), scale_by_group_lr(rates))


def map_moments(opt_state, fn):
  """Applies `fn` (params tree -> params tree) to Adam's `mu` and `nu` in `opt_state`.

  `opt_state` is the state of `make_optimizer`; the step counters are left untouched.
  """
  adam, group = opt_state
  return (adam._replace(mu=fn(adam.mu), nu=fn(adam.nu)), group)
