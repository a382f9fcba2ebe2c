"""Uncertainty a splat viewer shows: the model as 3DGS .ply files, and its uncertainty per
Gaussian beside them.

`write_uncertainty_plys(directory, model, per_gaussian)` writes three files, rows in the same
order (the model's live Gaussians):

* `coloured_by_uncertainty.ply`: the model in the reference 3DGS layout
  (`mfsample.data.ply`: 62 floats per Gaussian, SH padded to degree 3), geometry (centres,
  scales, rotations, opacities) exactly the model's, every colour replaced by a colour map of
  its share of U (magma: black = no share, through purple and orange to pale yellow = the
  largest; the scale's top is the 99th percentile of the shares, so one outlier does not
  darken the rest), view-dependent colour removed. Any splat viewer opens it (SuperSplat,
  gsplat's, the reference SIBR viewer): bright is where the model is unsure.
* `model_colours.ply`: the model as it is, in the same layout.
* `per_gaussian.ply`: a point cloud of the centres (x, y, z) with three float properties
  (`mfsample.gaussian_uncertainty.GaussianUncertainty`), for scripts (`plyfile`) and point
  cloud tools that colour by a property (CloudCompare):

    u_share        the Gaussian's share of U over the views (blending weight x pixel variance)
    position_std   the standard deviation of its centre over theta(z), world units
    colour_std     the standard deviation of its base colour over theta(z)

  They are not appended to the splat files: a viewer reading fixed 62-float records (SIBR)
  would misread every Gaussian after the first.

`experiments/render_ply.py` renders any of the splat files, or `model_colours.ply` coloured
by a property of `per_gaussian.ply`, to PNG.
"""

import os

import numpy as np

from mfsample.data.ply import write_gaussians_ply, write_ply
from mfsample.renderer.sh import rgb_to_sh_dc
from mfsample.your_data.export import colour_mapped

COLOURED = "coloured_by_uncertainty.ply"
OWN_COLOURS = "model_colours.ply"
PER_GAUSSIAN = "per_gaussian.ply"
# The properties of PER_GAUSSIAN: {name: field of GaussianUncertainty}.
PROPERTIES = {"u_share": "share", "position_std": "position_std", "colour_std": "colour_std"}


def share_colours(share, live, percentile=99.0):
  """[C, 3] colours in [0, 1] of the shares on magma over [0, percentile of the live ones]."""
  share = np.asarray(share, np.float64)
  live = np.asarray(live, bool)
  top = float(np.percentile(share[live], percentile)) if np.any(live) else 0.0
  top = top if top > 0 else max(float(share.max(initial=0.0)), 1e-30)
  return colour_mapped(share, top).astype(np.float64) / 255.0


def write_uncertainty_plys(directory, model, per_gaussian):
  """Writes the three files of the module docstring to `directory`.

  Args:
    directory: output folder (created if needed).
    model: `mfsample.model.Model`.
    per_gaussian: its `GaussianUncertainty` ([C] arrays).

  Returns:
    (path of coloured_by_uncertainty.ply, of model_colours.ply, of per_gaussian.ply).
  """
  os.makedirs(directory, exist_ok=True)
  live = np.asarray(model.mask, bool)
  mean = {g: np.asarray(v, np.float32) for g, v in model.params.mean.items()}
  own = write_gaussians_ply(os.path.join(directory, OWN_COLOURS), mean, live)
  colours = share_colours(per_gaussian.share, live)
  coloured = dict(mean, sh_dc=np.asarray(rgb_to_sh_dc(colours), np.float32))
  coloured.pop("sh_rest", None)  # (written as zeros: no view-dependent colour)
  path = write_gaussians_ply(os.path.join(directory, COLOURED), coloured, live)
  points = {axis: mean["means"][live, i] for i, axis in enumerate("xyz")}
  for name, field in PROPERTIES.items():
    values = np.asarray(getattr(per_gaussian, field), np.float32)[live]
    if not np.all(np.isfinite(values)):
      raise ValueError(f"per_gaussian.{field} has non-finite values")
    points[name] = values
  extras = write_ply(os.path.join(directory, PER_GAUSSIAN), points,
                     comments=(f"per Gaussian of {OWN_COLOURS} and {COLOURED}, same rows",))
  return path, own, extras
