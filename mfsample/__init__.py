"""mfsample: manifold sampling for differentiable uncertainty in Gaussian splatting."""

from mfsample.camera import Camera
from mfsample.gaussians import Gaussians
from mfsample.render import RenderOutput, RenderSettings, TileStats, render

__all__ = ["Camera", "Gaussians", "RenderOutput", "RenderSettings", "TileStats", "render"]
