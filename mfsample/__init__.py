"""mfsample: manifold sampling for differentiable uncertainty in Gaussian splatting.

The public API on one screen:

  Camera, Gaussians                 pytrees: a pinhole camera (OpenCV axes), 3D Gaussians
  render, RenderSettings            the tile-based 3DGS renderer and its static settings
  RenderOutput, TileStats           what render returns
  fit_budget, render_with_budget    grow the intersection budget instead of truncating
  testing                           synthetic scenes for tests, benchmarks and notebooks
"""

from mfsample import testing
from mfsample.camera import Camera
from mfsample.gaussians import Gaussians
from mfsample.render import RenderOutput, RenderSettings, TileStats, render
from mfsample.render.budget import fit_budget, render_with_budget

__all__ = [
    "Camera",
    "Gaussians",
    "RenderOutput",
    "RenderSettings",
    "TileStats",
    "fit_budget",
    "render",
    "render_with_budget",
    "testing",
]
