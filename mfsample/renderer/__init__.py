"""The tile-based Gaussian splatting renderer, in stages."""

from mfsample.renderer.render import RenderOutput, render
from mfsample.renderer.settings import RenderSettings
from mfsample.renderer.tiles import TileStats

__all__ = ["RenderOutput", "RenderSettings", "TileStats", "render"]
