"""Activated 3D Gaussians: the renderer's input.

These are constrained, physical values (positive scales, opacities in [0, 1]). Optimisers
work on raw, unconstrained parameters (`mfsample.model`), which are activated into this
pytree in exactly one place.
"""

import math

import chex
import jax.numpy as jnp

from mfsample._pytree import pytree_dataclass


@pytree_dataclass
class Gaussians:
  """N anisotropic 3D Gaussians with spherical-harmonics colour.

  Attributes:
    means: [N, 3] centres in world units.
    scales: [N, 3] standard deviations along the local axes (> 0, world units).
    quats: [N, 4] rotations as (w, x, y, z); need not be normalised. A zero quaternion is
      read as the identity rotation.
    opacities: [N] in [0, 1].
    sh: [N, K, 3] SH coefficients, K = (degree + 1)^2, degree in 0..3. The colour seen from
      direction d is max(sum_k sh_k Y_k(d) + 0.5, 0), as in 3DGS.
    mask: optional [N] bool; False marks padding slots of a fixed-capacity array, which never
      contribute to a render.
  """

  means: chex.Array
  scales: chex.Array
  quats: chex.Array
  opacities: chex.Array
  sh: chex.Array
  mask: chex.Array | None = None

  @property
  def num_gaussians(self):
    return self.means.shape[-2]

  @property
  def sh_degree(self):
    return sh_degree_from_size(self.sh.shape[-2])

  def validate(self):
    """Raises ValueError on inconsistent shapes or dtypes (called at trace time by render)."""
    n = self.means.shape[0] if self.means.ndim == 2 else None
    expected = {
        "means": (n, 3),
        "scales": (n, 3),
        "quats": (n, 4),
        "opacities": (n,),
    }
    if self.means.ndim != 2 or self.means.shape[-1] != 3:
      raise ValueError(f"Gaussians.means must have shape [N, 3], got {self.means.shape}.")
    for name, shape in expected.items():
      value = getattr(self, name)
      if tuple(value.shape) != shape:
        raise ValueError(f"Gaussians.{name} must have shape {list(shape)} (N={n}), "
                         f"got {list(value.shape)}.")
      if not jnp.issubdtype(value.dtype, jnp.floating):
        raise ValueError(f"Gaussians.{name} must be floating point, got {value.dtype}.")
    if self.sh.ndim != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3:
      raise ValueError(f"Gaussians.sh must have shape [N, K, 3] (N={n}), got {self.sh.shape}.")
    sh_degree_from_size(self.sh.shape[1])  # raises when K is not a square
    if self.mask is not None:
      if tuple(self.mask.shape) != (n,):
        raise ValueError(f"Gaussians.mask must have shape [{n}], got {list(self.mask.shape)}.")
      if self.mask.dtype != jnp.bool_:
        raise ValueError(f"Gaussians.mask must be boolean, got {self.mask.dtype}.")
    return self

  @classmethod
  def empty(cls, num, sh_degree=0, dtype=jnp.float32):
    """`num` masked-out placeholder Gaussians (unit scale, identity rotation)."""
    k = (sh_degree + 1) ** 2
    return cls(
        means=jnp.zeros((num, 3), dtype),
        scales=jnp.ones((num, 3), dtype),
        quats=jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0], dtype), (num, 1)),
        opacities=jnp.zeros((num,), dtype),
        sh=jnp.zeros((num, k, 3), dtype),
        mask=jnp.zeros((num,), bool),
    )


def sh_degree_from_size(k):
  """K = (degree + 1)^2 -> degree; ValueError unless K is 1, 4, 9 or 16."""
  degree = math.isqrt(k) - 1
  if (degree + 1) ** 2 != k or not 0 <= degree <= 3:
    raise ValueError(f"The SH axis must hold (degree + 1)^2 coefficients, a square for "
                     f"degree 0..3 (1, 4, 9 or 16); got {k}.")
  return degree
