"""The training objective (paper Eq. 9).

  L = 1/M sum_samples [ (1 - w) L1 + w (1 - SSIM) ] - lambda ||B_hat||_1,

with w = 0.2 (3DGS), the data term averaged over the M rendered samples, and the volume
term (entrywise L1 norm of B_hat, a stand-in for the volume of the parallelotope, paper
Sec. 4.3) applied only every `volume_every`-th step.
"""

import jax.numpy as jnp

from mfsample import metrics
from mfsample.samplers import b_hat_magnitude


def l1(pred, target):
  """Mean absolute error over all pixels and channels."""
  return jnp.mean(jnp.abs(pred - target))


def photometric(pred, target, ssim_weight=0.2):
  """(1 - w) L1 + w (1 - SSIM) of one image pair (3DGS loss; the data term of Eq. 9).

  Args:
    pred, target: [H, W, 3] images (H, W >= 11, the SSIM window).
    ssim_weight: w.

  Returns:
    scalar loss.
  """
  loss = (1.0 - ssim_weight) * l1(pred, target)
  if ssim_weight:
    loss = loss + ssim_weight * (1.0 - metrics.ssim(pred, target))
  return loss


def volume(model):
  """||B_hat||_1 over live Gaussians: the plain sum of |entries| (authors' code).

  The entrywise L1 norm has a constant gradient, so it neither vanishes for small B_hat
  nor explodes for large ones (paper Sec. 4.3).
  """
  total = jnp.zeros((), model.params.mean["means"].dtype)
  for b in b_hat_magnitude(model.params.b_hat).values():  # |relu(raw) * sign| = relu(raw)
    live = model.mask.reshape((-1,) + (1,) * (b.ndim - 1))
    total = total + jnp.sum(jnp.where(live, b, 0.0))
  return total
