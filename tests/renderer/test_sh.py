"""Real spherical harmonics: orthonormality, band sums, colour rule."""

import jax.numpy as jnp
import numpy as np
import pytest

from mfsample.renderer import sh


def _sphere_points(n):
  """Fibonacci sphere: near-uniform directions for quadrature (weights 4 pi / n)."""
  i = np.arange(n) + 0.5
  z = 1.0 - 2.0 * i / n
  phi = np.pi * (1.0 + 5**0.5) * i
  r = np.sqrt(1.0 - z * z)
  return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def test_basis_is_orthonormal_on_the_sphere():
  dirs = jnp.asarray(_sphere_points(200_000))
  y = np.asarray(sh.sh_basis(dirs, 3), np.float64)
  gram = y.T @ y * (4 * np.pi / len(dirs))
  np.testing.assert_allclose(gram, np.eye(16), atol=2e-3)


def test_band_sums_follow_the_addition_theorem():
  # sum_m Y_lm(d)^2 = (2l + 1) / (4 pi) for every direction d.
  dirs = jnp.asarray(_sphere_points(50))
  y = np.asarray(sh.sh_basis(dirs, 3))
  for band in range(4):
    block = y[:, band**2:(band + 1) ** 2]
    np.testing.assert_allclose((block**2).sum(1), (2 * band + 1) / (4 * np.pi), rtol=1e-5)


def test_band_one_matches_the_3dgs_signs():
  d = jnp.array([[0.6, 0.0, 0.8]])
  y = np.asarray(sh.sh_basis(d, 1))[0]
  c1 = 0.4886025119029199
  np.testing.assert_allclose(y, [0.28209479177387814, 0.0, c1 * 0.8, -c1 * 0.6], rtol=1e-6)


def test_colour_is_dc_plus_half_clamped_at_zero():
  dirs = jnp.asarray(_sphere_points(7))
  rgb = jnp.array([0.2, 0.7, 1.3])
  coeffs = jnp.zeros((7, 9, 3)).at[:, 0].set(sh.rgb_to_sh_dc(rgb))
  np.testing.assert_allclose(sh.sh_to_color(coeffs, dirs), np.tile(rgb, (7, 1)), atol=1e-6)
  dark = jnp.zeros((1, 1, 3)).at[:, 0].set(-10.0)
  np.testing.assert_array_equal(sh.sh_to_color(dark, dirs[:1]), 0.0)


@pytest.mark.parametrize("k", [2, 5, 25])
def test_non_square_or_too_large_sizes_raise(k):
  with pytest.raises(ValueError, match="square"):
    sh.eval_sh(jnp.zeros((1, k, 3)), jnp.array([[0.0, 0.0, 1.0]]))
