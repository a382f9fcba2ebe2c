"""Evaluation of a trained model: test metrics, renders and per-pixel uncertainty maps.

`mean_metrics` scores a batch of test views at once (`mfsample.mean_render`), `evaluate`
view by view with images and uncertainty maps.
"""

import os
import re
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import metrics
from mfsample import view_uncertainty as uncertainty_lib
from mfsample._json import atomic_path
from mfsample.mean_render import render_mean, render_mean_views
from mfsample.renderer.budget import render_with_budget


class EvalResult(NamedTuple):
  """Metrics (means over views, and per view) plus the images they were computed from.

  Attributes:
    metrics: {"psnr", "ssim", "lpips" (or None), "num_views"}: means over the views.
    per_view: {"psnr": [V], "ssim": [V], "lpips": [V] or None}.
    images: [V, H, W, 3] renders of the mean model, clipped to [0, 1].
    uncertainty: [V, H, W] per-pixel variance over samples (summed over RGB), or None.
  """

  metrics: dict
  per_view: dict
  images: np.ndarray
  uncertainty: np.ndarray | None


@jax.jit
def _image_metrics(pred, gt):
  """Per-view PSNR and SSIM of [V, H, W, 3] batches (`mfsample.metrics`)."""
  return metrics.psnr(pred, gt), metrics.ssim(pred, gt)


def mean_metrics(model, views, *, background, settings, lpips_fn=None):
  """Test metrics of a model's mean: {"psnr", "ssim", "lpips"}, means over `views`.

  All views are rendered in one jitted call (`render_mean_views`) and scored in batches
  (PSNR and SSIM of `mfsample.metrics`, LPIPS of `lpips_fn`), instead of one host round trip
  per view.

  Returns:
    (metrics dict, the settings that sufficed).
  """
  bg = jnp.asarray(background, jnp.float32)
  (pred, _), settings = render_with_budget(render_mean_views, settings, model, views.cameras,
                                          bg, stats_of=lambda out: out[1])
  gt = jnp.asarray(views.images, jnp.float32)
  psnr, ssim = _image_metrics(pred, gt)
  out = {"psnr": float(np.mean(psnr)), "ssim": float(np.mean(ssim)), "lpips": None}
  if lpips_fn is not None:
    out["lpips"] = float(np.mean(np.asarray(lpips_fn(pred, gt))))
  return out, settings


def evaluate(model, views, *, background, settings, lpips_fn=None, uncertainty_z=None):
  """Renders the mean model at every view and compares it with the images.

  Args:
    model: `Model`.
    views: `Views` with ground truth.
    background: [3] colour.
    settings: `RenderSettings` to start from (grown on overflow, never truncated).
    lpips_fn: optional `metrics.make_lpips(...)` function.
    uncertainty_z: optional `[M, *z_shape]` samples for the uncertainty maps (stochastic
      models only).

  Returns:
    `EvalResult`.
  """
  bg = jnp.asarray(background, jnp.float32)
  psnrs, ssims, lpipss, images, unc = [], [], [], [], []
  for i in range(len(views)):
    camera = views.cameras[i]
    out, settings = render_with_budget(render_mean, settings, model, camera, bg)
    pred = jnp.clip(out.rgb, 0.0, 1.0)
    gt = jnp.asarray(views.images[i], jnp.float32)
    psnrs.append(float(metrics.psnr(pred, gt)))
    ssims.append(float(metrics.ssim(pred, gt)))
    if lpips_fn is not None:
      lpipss.append(float(lpips_fn(pred, gt)))
    images.append(np.asarray(pred))
    if uncertainty_z is not None and model.spec.stochastic:
      u, settings = render_with_budget(uncertainty_lib.uncertainty, settings, model, camera,
                                       uncertainty_z, background=bg)
      unc.append(np.asarray(u.pixel_map))
  summary = {"psnr": float(np.mean(psnrs)), "ssim": float(np.mean(ssims)),
             "lpips": float(np.mean(lpipss)) if lpipss else None, "num_views": len(views)}
  per_view = {"psnr": psnrs, "ssim": ssims, "lpips": lpipss or None}
  return EvalResult(summary, per_view, np.stack(images), np.stack(unc) if unc else None)


def save_images(directory, result: EvalResult, views, num=None):
  """Writes renders, ground truth and uncertainty maps of the first `num` views as PNG.

  Uncertainty maps share one scale (the largest value over the written views) so that
  views compare; the raw float maps go to `uncertainty.npy`. Each file is written atomically.
  """
  import imageio.v3 as iio

  def write_png(name, image):
    with atomic_path(os.path.join(directory, name)) as tmp:
      iio.imwrite(tmp, image)

  num = len(views) if num is None else min(num, len(views))
  if num <= 0:
    return  # eval.save_images = 0: no images wanted
  os.makedirs(directory, exist_ok=True)
  to8 = lambda x: (np.clip(np.asarray(x), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
  names = views.names or tuple(f"view_{i:03d}" for i in range(len(views)))
  # NeRF Synthetic names are paths ("./test/r_0"): one flat file name per view.
  names = [re.sub(r"[^\w.-]+", "_", n.removeprefix("./")).strip("_") for n in names]
  if result.uncertainty is not None:
    scale = max(float(np.max(result.uncertainty[:num])), 1e-12)
    with atomic_path(os.path.join(directory, "uncertainty.npy")) as tmp:
      np.save(tmp, result.uncertainty[:num])
  for i in range(num):
    write_png(f"{names[i]}_render.png", to8(result.images[i]))
    write_png(f"{names[i]}_gt.png", to8(views.images[i]))
    if result.uncertainty is not None:
      write_png(f"{names[i]}_uncertainty.png", to8(result.uncertainty[i] / scale))
