"""Evaluation of a relightable field: held-out views under held-out lights.

The mean model is rendered once per test camera with the per-coefficient radiances as
features (`field.render_basis`); its image under any light is then the light's combination
of those, exactly (linearity), so K test lights cost one render per camera, not K. Images
are clamped to [0, 1] (prediction and ground truth alike) for PSNR / SSIM / LPIPS; the model
and the captures stay linear.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import metrics as metrics_lib
from mfsample.lighting import field
from mfsample.lighting import lights as lights_lib
from mfsample.renderer.budget import render_with_budget
from mfsample.renderer.settings import RenderSettings

METRICS = ("psnr", "ssim", "lpips")


@functools.partial(jax.jit, static_argnames=("settings",))
def _mean_basis(model, cameras, *, settings):
  def one(camera):
    images, out = field.render_basis(model.params.mean, model.mask, camera, settings=settings)
    return images, out.stats

  return jax.lax.map(one, cameras)  # [T, H, W, n, 3]


def relight_views(model, cameras, lights, *, settings: RenderSettings):
  """Linear images [K, T, H, W, 3] of the mean model under each of `lights` [K, n] at each
  of `cameras` [T] (unclamped), and the settings that sufficed."""
  _, n = field.coefficient_counts(model)
  lights = lights_lib.check_lights(lights, n)
  (basis, _), settings = render_with_budget(_mean_basis, settings, model, cameras,
                                            stats_of=lambda out: out[1], what="evaluation")
  return np.einsum("thwbc,kb->kthwc", np.asarray(basis, np.float64), lights), settings


@jax.jit
def _psnr_ssim(pred, gt):
  return metrics_lib.psnr(pred, gt), metrics_lib.ssim(pred, gt)


def image_metrics(pred, gt, lpips_fn=None, batch=64):
  """Per-image PSNR, SSIM (and LPIPS) of [B, H, W, 3] images clamped to [0, 1].

  Returns:
    {"psnr": [B], "ssim": [B], "lpips": [B] or None} numpy arrays.
  """
  pred = np.clip(np.asarray(pred, np.float32), 0.0, 1.0)
  gt = np.clip(np.asarray(gt, np.float32), 0.0, 1.0)
  out = {"psnr": [], "ssim": [], "lpips": [] if lpips_fn is not None else None}
  for i in range(0, len(pred), batch):
    p, g = jnp.asarray(pred[i:i + batch]), jnp.asarray(gt[i:i + batch])
    psnr, ssim = _psnr_ssim(p, g)
    out["psnr"].append(np.asarray(psnr))
    out["ssim"].append(np.asarray(ssim))
    if lpips_fn is not None:
      out["lpips"].append(np.asarray(lpips_fn(p, g)))
  return {k: None if v is None else np.concatenate(v).astype(np.float64)
          for k, v in out.items()}


def evaluate_relit(model, cameras, lights, ground_truth, kinds, *, settings, lpips_fn=None):
  """Test metrics of the mean model under held-out lights at held-out cameras.

  Args:
    model: a relightable `Model`.
    cameras: `Camera` [T].
    lights: [K, n] test lights.
    ground_truth: [K, T, H, W, 3] captures (linear).
    kinds: K strings (e.g. "environment", "random"): metrics are also given per kind.
    settings: starting `RenderSettings`.
    lpips_fn: optional `mfsample.metrics.make_lpips(...)`.

  Returns:
    (metrics, predictions [K, T, H, W, 3] linear, settings). `metrics` holds the means over
    every (light, camera) image ("psnr", "ssim", "lpips" or None), "by_kind" {kind: the
    same}, and "per_light" {metric: [K] means over the cameras}.
  """
  pred, settings = relight_views(model, cameras, lights, settings=settings)
  k, t = pred.shape[:2]
  gt = np.asarray(ground_truth)
  if gt.shape != pred.shape:
    raise ValueError(f"ground truth has shape {gt.shape}, the renders {pred.shape}")
  per = image_metrics(pred.reshape((k * t,) + pred.shape[2:]),
                      gt.reshape((k * t,) + gt.shape[2:]), lpips_fn)
  per = {m: None if v is None else v.reshape(k, t) for m, v in per.items()}

  def means(rows):
    return {m: None if per[m] is None else float(np.mean(per[m][rows])) for m in METRICS}

  kinds = tuple(kinds)
  out = means(np.arange(k))
  out["by_kind"] = {kind: means(np.asarray([i for i in range(k) if kinds[i] == kind]))
                    for kind in dict.fromkeys(kinds)}
  out["per_light"] = {m: None if per[m] is None else np.mean(per[m], axis=1).tolist()
                      for m in METRICS}
  return out, pred, settings
