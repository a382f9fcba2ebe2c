"""Uncertainty a splat viewer shows: the model as 3DGS .ply files that carry it per Gaussian.

`write_uncertainty_plys(directory, model, per_gaussian)` writes two files in the standard
3DGS layout (`mfsample.data.ply`), geometry (centres, scales, rotations, opacities) exactly
the model's, with three extra float properties per Gaussian
(`mfsample.gaussian_uncertainty.GaussianUncertainty`):

  u_share        the Gaussian's share of U over the views (blending weight x pixel variance)
  position_std   the standard deviation of its centre over theta(z), world units
  colour_std     the standard deviation of its base colour over theta(z)

* `coloured_by_uncertainty.ply`: every Gaussian's colour replaced by a colour map of its
  share (magma: black = no share of U, through purple and orange to pale yellow = the largest;
  the scale's top is the 99th percentile of the shares, so one outlier does not darken the
  rest), view-dependent colour removed. Open it in SuperSplat or any splat viewer: bright is
  where the model is unsure.
* `model_colours.ply`: the model's own colours, the same properties: a viewer that can colour
  by a property (or a script) reads them there.
"""

import os

import numpy as np

from mfsample.data.ply import ply_arrays, write_ply
from mfsample.renderer.sh import rgb_to_sh_dc
from mfsample.your_data.export import colour_mapped

COLOURED = "coloured_by_uncertainty.ply"
OWN_COLOURS = "model_colours.ply"


def share_colours(share, live, percentile=99.0):
  """[C, 3] colours in [0, 1] of the shares on magma over [0, percentile of the live ones]."""
  share = np.asarray(share, np.float64)
  live = np.asarray(live, bool)
  top = float(np.percentile(share[live], percentile)) if np.any(live) else 0.0
  top = top if top > 0 else max(float(share.max(initial=0.0)), 1e-30)
  return colour_mapped(share, top).astype(np.float64) / 255.0


def write_uncertainty_plys(directory, model, per_gaussian):
  """Writes the two files of the module docstring to `directory`.

  Args:
    directory: output folder (created if needed).
    model: `mfsample.model.Model`.
    per_gaussian: its `GaussianUncertainty` ([C] arrays).

  Returns:
    (path of coloured_by_uncertainty.ply, path of model_colours.ply).
  """
  os.makedirs(directory, exist_ok=True)
  extra = {"u_share": per_gaussian.share, "position_std": per_gaussian.position_std,
           "colour_std": per_gaussian.colour_std}
  mean = {g: np.asarray(v, np.float32) for g, v in model.params.mean.items()}
  own = write_ply(os.path.join(directory, OWN_COLOURS), ply_arrays(mean, model.mask, extra))
  colours = share_colours(per_gaussian.share, model.mask)
  coloured = dict(mean, sh_dc=np.asarray(rgb_to_sh_dc(colours), np.float32))
  if "sh_rest" in coloured:
    coloured["sh_rest"] = np.zeros_like(coloured["sh_rest"])
  path = write_ply(os.path.join(directory, COLOURED), ply_arrays(coloured, model.mask, extra))
  return path, own
