"""Does U rank the candidate views as the model's error there does? (The premise of Ours (Sel.))

For a trained model, the cameras it was trained on and candidate cameras (with their
ground-truth images when there are any):

  U_c     = U (Eq. 10) of candidate c, rendered at 1 / `score_downscale` of its size,
  e_c     = mean squared error of the model's mean render against candidate c's image,
  rho     = Spearman's rank correlation of U_c against e_c over the candidates.

rho near 1 means that picking the highest-U candidate picks the view the model gets most
wrong. Beside it, the rank correlation of U and of the error with the angle to the nearest
training view tells how much of either is mere coverage. The uncertainty-quality experiment
measures it on planning pools, the next-views job on a user's capture.
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from mfsample import interrupts
from mfsample import view_uncertainty as unc
from mfsample.camera import Camera
from mfsample.mean_render import render_mean_views
from mfsample.metrics import spearman
from mfsample.planning import poses
from mfsample.renderer import RenderSettings
from mfsample.renderer.budget import render_with_budget


class UError(NamedTuple):
  """U against the error over the candidates (numpy; [B] = candidates).

  Attributes:
    u: [B] U of each candidate.
    error: [B] mean squared error of the mean render there, or None without images.
    angle: [B] angle (radians) to the nearest training view, seen from `center`, or None
      without training cameras.
    rho_u_error: Spearman's rho of u against error (None without images, or undefined:
      fewer than 3 candidates, or a constant side).
    rho_u_angle: Spearman's rho of u against angle (None without training cameras).
    rho_error_angle: Spearman's rho of error against angle (None without either).
    score_settings: the `RenderSettings` that sufficed for U.
    mean_settings: those that sufficed for the mean renders (None without images).
  """

  u: np.ndarray
  error: np.ndarray | None
  angle: np.ndarray | None
  rho_u_error: float | None
  rho_u_angle: float | None
  rho_error_angle: float | None
  score_settings: RenderSettings
  mean_settings: RenderSettings | None


def _rho(a, b):
  """Spearman's rho (`metrics.spearman`), None where undefined or without one of them."""
  return None if a is None or b is None else spearman(a, b)


def u_against_error(model, cameras: Camera, z, *, background, images=None, train_cameras=None,
                    center=(0.0, 0.0, 0.0), score_downscale=1, score_settings=None,
                    mean_settings=None, batch=None, on_batch=None) -> UError:
  """U of every candidate camera and, with their images, how well it ranks the model's error.

  Args:
    model: a trained `mfsample.model.Model`.
    cameras: `Camera` [B] of the candidates.
    z: `[M, *z_shape]` samples of U (`mfsample.samplers.sample_z`).
    background: [3] colour behind the Gaussians.
    images: optional [B, H, W, 3] ground truth of the candidates.
    train_cameras: optional `Camera` [V] the model was trained on (the angle to the nearest).
    center: the centre the cameras look at (for the angles).
    score_downscale: U is computed at 1 / score_downscale of the image size (as planning
      scores candidates); the error at full size.
    score_settings: `RenderSettings` U's renders start from (default: a small budget).
    mean_settings: those the mean renders start from (default: a small budget).
    batch: candidates per call (memory holds one batch's renders; None: all at once).
    on_batch: optional callback(number of candidates done) after every batch (progress).

  Returns:
    `UError`.
  """
  num = cameras.batch_shape[0]
  batch = num if batch is None else max(1, min(int(batch), num))
  bg = jnp.asarray(background, jnp.float32)
  u, error = np.zeros(num), (None if images is None else np.zeros(num))
  score_settings = score_settings or RenderSettings(max_intersections=1 << 12)
  mean_settings = mean_settings or RenderSettings(max_intersections=1 << 14)
  for start in range(0, num, batch):
    interrupts.check(f"scoring candidates {start}..")
    # The last batch repeats its last camera up to the batch size: one compilation.
    index = np.minimum(np.arange(start, start + batch), num - 1)
    keep = slice(0, min(batch, num - start))
    chunk = cameras[index]
    scores, score_settings = unc.score_cameras(
        model, poses.downscale_camera(chunk, int(score_downscale)), z, settings=score_settings,
        background=bg, num_devices=1)
    u[start:start + batch] = np.asarray(scores.values)[keep]
    if images is not None:
      (pred, _), mean_settings = render_with_budget(
          render_mean_views, mean_settings, model, chunk, bg, stats_of=lambda out: out[1])
      truth = np.asarray(images)[index]
      error[start:start + batch] = np.mean((np.asarray(pred) - truth) ** 2,
                                           axis=(1, 2, 3))[keep]
    if on_batch is not None:
      on_batch(min(start + batch, num))
  angle = None
  if train_cameras is not None:
    both = Camera(*(jnp.concatenate([a, b]) for a, b in zip(
        (train_cameras.world_to_camera, train_cameras.fx, train_cameras.fy, train_cameras.cx,
         train_cameras.cy),
        (cameras.world_to_camera, cameras.fx, cameras.fy, cameras.cx, cameras.cy),
        strict=True)), cameras.width, cameras.height)
    v = train_cameras.batch_shape[0]
    angle = poses.angle_to_nearest(both, list(range(v)), center)[v:]
  return UError(u, error, angle, _rho(u, error), _rho(u, angle), _rho(error, angle),
                score_settings, mean_settings if images is not None else None)
