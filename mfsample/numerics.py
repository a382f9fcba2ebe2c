"""Named safe numerics.

Each helper keeps both the value and its gradient finite where the textbook formula has a
singularity. The pattern is the "double where": the unsafe input is replaced *before* the
singular operation, so the discarded branch never produces an inf or NaN whose zero
cotangent would still turn into NaN (0 * inf) in the backward pass.
"""

import jax.numpy as jnp

TINY = 1e-12


def safe_norm(x, axis=-1, keepdims=False, eps=TINY):
  """Euclidean norm with a finite gradient at x = 0 (where it returns 0)."""
  sq = jnp.sum(x * x, axis=axis, keepdims=keepdims)
  nonzero = sq > eps
  return jnp.where(nonzero, jnp.sqrt(jnp.where(nonzero, sq, 1.0)), 0.0)


def safe_normalize(x, axis=-1, fallback=None, eps=TINY):
  """x / |x|, returning `fallback` (default: zeros) where |x|^2 <= eps."""
  sq = jnp.sum(x * x, axis=axis, keepdims=True)
  nonzero = sq > eps
  unit = x / jnp.sqrt(jnp.where(nonzero, sq, 1.0))
  if fallback is None:
    fallback = jnp.zeros_like(x)
  return jnp.where(nonzero, unit, jnp.broadcast_to(fallback, x.shape))


def safe_sqrt(x, eps=TINY):
  """sqrt(max(x, 0)) with a finite gradient at 0."""
  positive = x > eps
  return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), 0.0)


def safe_div(num, den, eps=TINY):
  """num / den, 0 where |den| <= eps."""
  ok = jnp.abs(den) > eps
  return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


def nan_to_zero(x):
  """Replaces non-finite entries by zero (used on discarded branches only)."""
  return jnp.where(jnp.isfinite(x), x, 0.0)
