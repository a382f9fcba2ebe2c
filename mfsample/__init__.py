"""mfsample: manifold sampling for differentiable uncertainty in Gaussian splatting.

The functional API on one screen (docs/api.md):

  Camera, Gaussians                 pytrees: a pinhole camera (OpenCV axes), 3D Gaussians
  orbit_camera, sphere_cameras      jnp camera generators (they jit and vmap)
  render, RenderSettings            the tile-based 3DGS renderer and its static settings
  RenderOutput, TileStats           what render returns
  fit_budget, render_with_budget    grow the intersection budget instead of truncating
  Model, SamplerSpec, init_model    a stochastic 3DGS model: raw mean, B_hat, mask (Sec. 4.2)
  sample, mean_gaussians            theta(z) = mean + B_hat z as Gaussians; the mean model
  sample_z                          z of U: scrambled Sobol (low rank) or uniforms
  TrainSettings, fit                the paper's training (Eq. 9, densification) on any Views
  fit_b_hat                         B_hat fitted to a pretrained model's frozen mean
  uncertainty                       U of a camera (Eq. 10) and its per-pixel map
  next_views, optimize_view         the next views: select among candidates, or ascend U
  next_lights, optimize_light       the same for the lights of a relightable field
  Views                             posed images (every loader's and `fit`'s currency)
  testing                           synthetic scenes for tests, benchmarks and notebooks

Subpackages: `renderer` (the renderer's stages and budgets), `train`, `lighting`, `data`
(loaders and exports), `baselines` (FisherRF, ActiveNeRF, ACP), `scenes` (the Mitsuba
capture oracle), `metrics`. The experiment jobs (configs and workdirs) sit on top:
`mfsample.jobs` and each job's runner (`train.experiment`, `planning.runner`, ...);
docs/architecture.md maps them all.
"""

from mfsample import testing
from mfsample.camera import Camera
from mfsample.data.views import Views
from mfsample.gaussians import Gaussians
from mfsample.model import Model, init_model, mean_gaussians, sample
from mfsample.orbits import orbit_camera, sphere_cameras
from mfsample.renderer import RenderOutput, RenderSettings, TileStats, render
from mfsample.renderer.budget import fit_budget, render_with_budget
from mfsample.samplers import SamplerSpec, sample_z
from mfsample.selection import next_lights, next_views, optimize_light, optimize_view
from mfsample.train.loop import fit
from mfsample.train.posthoc import fit_b_hat
from mfsample.train.settings import TrainSettings
from mfsample.view_uncertainty import uncertainty

__version__ = "0.2.0"

__all__ = [
    "Camera",
    "Gaussians",
    "Model",
    "RenderOutput",
    "RenderSettings",
    "SamplerSpec",
    "TileStats",
    "TrainSettings",
    "Views",
    "fit",
    "fit_b_hat",
    "fit_budget",
    "init_model",
    "mean_gaussians",
    "next_lights",
    "next_views",
    "optimize_light",
    "optimize_view",
    "orbit_camera",
    "render",
    "render_with_budget",
    "sample",
    "sample_z",
    "sphere_cameras",
    "testing",
    "uncertainty",
]
