"""Named safe numerics.

A helper keeps both the value and its gradient finite where the textbook formula has a
singularity. The pattern is the "double where": the unsafe input is replaced *before* the
singular operation, so the discarded branch never produces an inf or NaN whose zero
cotangent would still turn into NaN (0 * inf) in the backward pass.
"""

import jax.numpy as jnp

TINY = 1e-12

# The largest world coordinate (camera centres, initial points, Gaussian centres) the float32
# maths handles: squared distances of coordinates up to 1e18 stay below float32's maximum
# (3.4e38) with room for sums of three; beyond it `safe_normalize` squares to inf and a
# camera looking at the scene gets a zero rotation.
WORLD_LIMIT = 1e18


def safe_normalize(x, axis=-1, fallback=None, eps=TINY):
  """x / |x|, returning `fallback` (default: zeros) where |x|^2 <= eps."""
  sq = jnp.sum(x * x, axis=axis, keepdims=True)
  nonzero = sq > eps
  unit = x / jnp.sqrt(jnp.where(nonzero, sq, 1.0))
  if fallback is None:
    fallback = jnp.zeros_like(x)
  return jnp.where(nonzero, unit, jnp.broadcast_to(fallback, x.shape))
