"""mfsample: manifold sampling for differentiable uncertainty in Gaussian splatting."""

from mfsample.camera import Camera
from mfsample.gaussians import Gaussians
from mfsample.model import Model, SamplerSpec, mean_gaussians
from mfsample.render import RenderOutput, RenderSettings, TileStats, render
from mfsample.samplers import draw_z, sample, sobol_z
# `mfsample.train` stays the subpackage (its `train` function is `mfsample.train.train`).
from mfsample.train import train_and_evaluate

__all__ = [
    "Camera", "Gaussians", "Model", "RenderOutput", "RenderSettings", "SamplerSpec",
    "TileStats", "draw_z", "mean_gaussians", "render", "sample", "sobol_z",
    "train_and_evaluate",
]
