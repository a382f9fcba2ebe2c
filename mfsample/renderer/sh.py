"""Real spherical harmonics, degrees 0-3, in the basis and ordering of 3DGS.

Index k = l^2 + l + m for band l and order m = -l..l. The functions are the orthonormal real
SH with the Condon-Shortley phase (hence the minus signs in band 1), so that
integral over the sphere of Y_j Y_k = delta_jk. The same basis lights scenes in the capture
oracle (`mfsample.scenes`) and drives relighting, so it lives in one place.
"""

import jax.numpy as jnp

from mfsample.gaussians import sh_degree_from_size
from mfsample.renderer.precision import MATMUL

_C0 = 0.28209479177387814
_C1 = 0.4886025119029199
_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
       0.5462742152960396)
_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
       -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


def sh_basis(dirs, degree):
  """Evaluates the real SH basis.

  Args:
    dirs: [..., 3] unit directions (x, y, z).
    degree: 0..3 (static).

  Returns:
    [..., (degree + 1)^2] basis values Y_k(dirs).
  """
  if not 0 <= degree <= 3:
    raise ValueError(f"SH degree must be in 0..3, got {degree}")
  x, y, z = dirs[..., 0], dirs[..., 1], dirs[..., 2]
  out = [jnp.full_like(x, _C0)]
  if degree >= 1:
    out += [-_C1 * y, _C1 * z, -_C1 * x]
  if degree >= 2:
    xx, yy, zz = x * x, y * y, z * z
    out += [
        _C2[0] * x * y,
        _C2[1] * y * z,
        _C2[2] * (2.0 * zz - xx - yy),
        _C2[3] * x * z,
        _C2[4] * (xx - yy),
    ]
  if degree >= 3:
    out += [
        _C3[0] * y * (3.0 * xx - yy),
        _C3[1] * x * y * z,
        _C3[2] * y * (4.0 * zz - xx - yy),
        _C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
        _C3[4] * x * (4.0 * zz - xx - yy),
        _C3[5] * z * (xx - yy),
        _C3[6] * x * (xx - 3.0 * yy),
    ]
  return jnp.stack(out, axis=-1)


def eval_sh(coeffs, dirs):
  """Sum_k coeffs_k Y_k(dirs).

  Args:
    coeffs: [..., K, C] coefficients, K = (degree + 1)^2.
    dirs: [..., 3] unit directions, broadcastable against coeffs' leading axes.

  Returns:
    [..., C] values.
  """
  degree = sh_degree_from_size(coeffs.shape[-2])
  basis = sh_basis(dirs, degree)
  return jnp.einsum("...k,...kc->...c", basis, coeffs, precision=MATMUL)


def sh_to_color(coeffs, dirs):
  """3DGS colour: max(SH(dirs) + 0.5, 0). [..., K, 3], [..., 3] -> [..., 3]."""
  return jnp.maximum(eval_sh(coeffs, dirs) + 0.5, 0.0)


def rgb_to_sh_dc(rgb):
  """The DC coefficient whose 3DGS colour is `rgb` (inverse of the +0.5 offset)."""
  return (rgb - 0.5) / _C0
