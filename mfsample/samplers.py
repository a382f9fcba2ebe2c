"""Manifold samplers: theta(z) = mean + B_hat z, behind one interface (paper Sec. 4.2).

`sample(model, z)` returns the `Gaussians` of one realisation; vmap it over a leading axis
of z for M samples. The shape of z depends on the sampler (`z_shape`):

| kind          | z              | covariance of theta                          |
| ------------- | -------------- | -------------------------------------------- |
| deterministic | [0]            | 0 (plain 3DGS, the speed baseline)           |
| diagonal      | [C, D]         | diagonal: every entry its own uniform        |
| block         | [C, k]         | block diagonal, one rank-k block per Gaussian|
| lowrank       | [k]            | B_hat B_hat^T, rank k (paper Eq. 7)          |

C is the capacity and D the number of stochastic entries per Gaussian (groups in
`model.GROUP_ORDER` order, each flattened). z is uniform on [-1, 1]: for the low-rank sampler a
scrambled Sobol sequence (`sobol_z`, paper Sec. 4.3), for the per-Gaussian samplers
pseudo-random uniforms (`draw_z`; Sobol sequences stop at 21201 dimensions and bring
nothing at millions).

With z ~ U[-1, 1] (variance 1/3 per component), the per-entry variance of theta is
sum_j B_hat[:, j]^2 / 3 (`entry_variance`).
"""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks
from mfsample.model import GROUP_ORDER, Model, activate, generator

# Dimensions of scipy's Sobol direction numbers (Joe and Kuo).
_SOBOL_MAX_DIM = 21201


def _ordered(groups):
  return sorted(groups, key=GROUP_ORDER.index)


def channels_per_gaussian(model: Model):
  """D: stochastic entries per Gaussian (the trailing axis of a diagonal z)."""
  spread = model.params.spread
  cols = len(model.spec.columns)
  return sum(math.prod(spread[g].shape[1:spread[g].ndim - cols]) for g in spread)


def z_shape(model: Model):
  """The shape of one z for `sample(model, z)` (see the module docstring)."""
  spec = model.spec
  if not spec.stochastic:
    return (0,)
  if spec.kind == "lowrank":
    return (spec.rank,)
  if spec.kind == "block":
    return (model.capacity, spec.rank)
  return (model.capacity, channels_per_gaussian(model))


def perturb(model: Model, z):
  """Raw parameters of the realisation theta(z) = mean + B_hat z.

  Args:
    model: `Model`.
    z: one z of shape `z_shape(model)`, entries in [-1, 1].

  Returns:
    {group: [C, ...]} raw parameters (deterministic groups are the mean's arrays).
  """
  spec = model.spec
  mean = model.params.mean
  if not spec.stochastic:
    return dict(mean)
  z = jnp.asarray(z, mean["means"].dtype)
  if z.shape != z_shape(model):
    raise ValueError(f"z must have shape {z_shape(model)} for the {spec.kind} sampler, "
                     f"got {z.shape}")
  b_hat = generator(model.params.spread, model.signs)
  out = dict(mean)
  offset = 0
  for g in _ordered(b_hat):
    b = b_hat[g]
    if spec.kind == "lowrank":
      delta = b @ z  # [C, ..., k] @ [k]
    elif spec.kind == "block":
      zc = z.reshape((z.shape[0],) + (1,) * (b.ndim - 2) + (z.shape[1],))
      delta = jnp.sum(b * zc, axis=-1)
    else:  # diagonal
      size = math.prod(b.shape[1:])
      delta = b * z[:, offset:offset + size].reshape(b.shape)
      offset += size
    out[g] = mean[g] + delta
  return out


def sample(model: Model, z):
  """`Gaussians` of the realisation theta(z) (paper Eq. 7). Vmap over z for M samples."""
  return activate(perturb(model, z), model.mask, model.sh_degree)


def entry_variance(model: Model):
  """{group: [C, ...]} per-entry variance of theta for z ~ U[-1, 1]: sum_j B_hat_j^2 / 3."""
  b_hat = generator(model.params.spread, model.signs)
  cols = len(model.spec.columns)
  out = {}
  for g, b in b_hat.items():
    sq = b * b
    out[g] = (jnp.sum(sq, axis=-1) if cols else sq) / 3.0
  return out


def sobol_z(num, dim, seed, offset=0):
  """Points `offset .. offset + num - 1` of a scrambled Sobol sequence, mapped to [-1, 1].

  Deterministic in (dim, seed): a resumed run regenerates exactly the same points.

  Args:
    num: number of points.
    dim: dimension k (1 <= k <= 21201).
    seed: scrambling seed.
    offset: index of the first point.

  Returns:
    [num, dim] float32 numpy array in [-1, 1].
  """
  from scipy.stats import qmc  # host-only dependency, imported where used
  for name, value, low in (("num", num, 0), ("dim", dim, 0), ("offset", offset, 0)):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
      raise ValueError(f"sobol_z: {name} must be an integer >= {low}, got {value!r}")
  arg_checks.check_seed("sobol_z: seed", seed)
  if dim > _SOBOL_MAX_DIM:
    raise ValueError(f"sobol_z: dim = {dim} exceeds the {_SOBOL_MAX_DIM} dimensions of the "
                     "Sobol direction numbers (use draw_z's uniforms instead)")
  if dim < 1:
    return np.zeros((num, 0), np.float32)
  engine = qmc.Sobol(d=dim, scramble=True, seed=seed)
  if offset:
    engine.fast_forward(offset)
  with warnings.catch_warnings():
    # Balance properties need powers of two; for a sequence consumed step by step we
    # accept the warning's premise.
    warnings.simplefilter("ignore", UserWarning)
    points = engine.random(num)
  return (2.0 * points - 1.0).astype(np.float32)


def draw_z(model: Model, num, key, sobol_rows=None):
  """M = `num` z's for `model`'s sampler.

  Args:
    model: `Model` (only its spec and shapes are used).
    num: M, number of samples (static).
    key: PRNG key for the pseudo-random samplers (and lowrank without Sobol rows).
    sobol_rows: optional [M, k] rows of `sobol_z` for the low-rank sampler.

  Returns:
    [M, *z_shape(model)] in [-1, 1].
  """
  if isinstance(num, bool) or not isinstance(num, (int, np.integer)) or num < 0:
    raise ValueError(f"draw_z: num must be an integer >= 0, got {num!r}")
  shape = (num,) + z_shape(model)
  dtype = model.params.mean["means"].dtype
  if model.spec.kind == "lowrank" and sobol_rows is not None:
    arg_checks.check_shape("draw_z: sobol_rows", sobol_rows, shape, "rows of sobol_z")
    return jnp.asarray(sobol_rows, dtype).reshape(shape)
  arg_checks.check_key(key, "draw_z: key")
  return jax.random.uniform(key, shape, dtype, minval=-1.0, maxval=1.0)
