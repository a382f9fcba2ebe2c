"""Does U rank the candidate views as the model's error there does? (The premise of Ours (Sel.))

For a trained model, the views it was trained on and a pool of candidate views with their
ground-truth images:

  U_c     = U (Eq. 10) of candidate c, rendered at 1 / `score_downscale` of its size,
  e_c     = mean squared error of the model's mean render against candidate c's image,
  rho     = Spearman's rank correlation of U_c against e_c over the unused candidates.

rho near 1 means that picking the highest-U candidate picks the view the model gets most
wrong. Beside it, the rank correlation of U and of the error with the angle to the nearest
training view tells how much of either is mere coverage.
"""

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from mfsample import uncertainty as unc
from mfsample.planning import poses
from mfsample.renderer import RenderSettings
from mfsample.renderer.budget import render_with_budget
from mfsample.train.evaluate import render_mean_views


class UError(NamedTuple):
  """U against the error over the unused candidates (numpy; [B'] = unused candidates).

  Attributes:
    u: [B'] U of each unused candidate.
    error: [B'] mean squared error of the mean render there.
    angle: [B'] angle (radians) to the nearest training view, seen from the sphere centre.
    rho_u_error: Spearman's rho of u against error.
    rho_u_angle: Spearman's rho of u against angle.
    rho_error_angle: Spearman's rho of error against angle.
    settings: {"mean", "score"}: the render settings that sufficed (reuse them next call).
  """

  u: np.ndarray
  error: np.ndarray
  angle: np.ndarray
  rho_u_error: float
  rho_u_angle: float
  rho_error_angle: float
  settings: dict


def u_against_error(model, candidates, used, z, *, background, center=(0.0, 0.0, 0.0),
                    score_downscale=1, settings=None):
  """Measures how well U ranks the unused `candidates` by the model's error there.

  Args:
    model: a trained `mfsample.model.Model`.
    candidates: `Views` (images [B, H, W, 3] and cameras) of the candidate pool.
    used: indices of the candidates the model was trained on (left out of the ranking).
    z: [M, *z_shape] samples of U (`uncertainty.uncertainty_z`).
    background: [3] colour behind the Gaussians.
    center: the centre the cameras look at (for the angle to the nearest training view).
    score_downscale: U is computed at 1 / score_downscale of the image size (as planning
      scores candidates); the error at full size.
    settings: optional {"mean", "score"} `RenderSettings` to start from.

  Returns:
    `UError`.
  """
  from scipy.stats import spearmanr

  settings = dict(settings or {})
  bg = jnp.asarray(background, jnp.float32)
  (pred, _), settings["mean"] = render_with_budget(
      render_mean_views, settings.get("mean", RenderSettings(max_intersections=1 << 14)), model,
      candidates.cameras, bg, stats_of=lambda out: out[1])
  error = np.mean((np.asarray(pred) - np.asarray(candidates.images)) ** 2, axis=(1, 2, 3))
  small = poses.downscale_camera(candidates.cameras, int(score_downscale))
  scores, settings["score"] = unc.score_cameras(
      model, small, z, settings=settings.get("score", RenderSettings(max_intersections=1 << 12)),
      background=bg, num_devices=1)
  unused = np.ones(len(candidates), bool)
  unused[np.asarray(used, int)] = False
  u = np.asarray(scores.values)[unused]
  angle = poses.angle_to_nearest(candidates.cameras, list(used), center)[unused]
  error = error[unused]
  rho = lambda a, b: float(spearmanr(a, b).correlation)
  return UError(u, error, angle, rho(u, error), rho(u, angle), rho(error, angle), settings)
