"""mfsample: manifold sampling for differentiable uncertainty in Gaussian splatting.

The public API on one screen:

  Camera, Gaussians                 pytrees: a pinhole camera (OpenCV axes), 3D Gaussians
  render, RenderSettings            the tile-based 3DGS renderer and its static settings
  RenderOutput, TileStats           what render returns
  fit_budget, render_with_budget    grow the intersection budget instead of truncating
  Model, SamplerSpec, init_model    a stochastic 3DGS model: raw mean, B_hat, mask (Sec. 4.2)
  sample, mean_gaussians            theta(z) = mean + B_hat z as Gaussians; the mean model
  sobol_z, draw_z                   z for the samplers: scrambled Sobol / uniform in [-1, 1]
  train_and_evaluate                the training experiment (`mfsample.train.train` for Views)
  uncertainty                       module: uncertainty(model, camera, z) -> U (Eq. 10)
                                    and its per-pixel map; uncertainty_z; score_cameras
  run_camera_planning               the active camera planning protocol (the main job)
  testing                           synthetic scenes for tests, benchmarks and notebooks

Subpackages: `renderer` (the renderer's stages and budgets), `train`, `planning`,
`lighting`, `quality`, `next_views`, `baselines` (FisherRF, ActiveNeRF, ACP), `data`,
`scenes` (the Mitsuba capture oracle), `metrics`, `model`, `samplers`, `jobs` (the skeleton
every experiment runs on); docs/architecture.md maps them all.
"""

# `uncertainty` is the module: exporting its function of the same name would shadow it.
from mfsample import testing, uncertainty
from mfsample.camera import Camera
from mfsample.gaussians import Gaussians
from mfsample.model import Model, SamplerSpec, init_model, mean_gaussians
from mfsample.planning import run_camera_planning
from mfsample.renderer import RenderOutput, RenderSettings, TileStats, render
from mfsample.renderer.budget import fit_budget, render_with_budget
from mfsample.samplers import draw_z, sample, sobol_z

# `mfsample.train` stays the subpackage (its `train` function is `mfsample.train.train`).
from mfsample.train import train_and_evaluate

__all__ = [
    "Camera",
    "Gaussians",
    "Model",
    "RenderOutput",
    "RenderSettings",
    "SamplerSpec",
    "TileStats",
    "draw_z",
    "fit_budget",
    "init_model",
    "mean_gaussians",
    "render",
    "render_with_budget",
    "run_camera_planning",
    "sample",
    "sobol_z",
    "testing",
    "train_and_evaluate",
    "uncertainty",
]
