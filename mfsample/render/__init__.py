"""The tile-based Gaussian splatting renderer, in stages."""

from mfsample.render.render import RenderOutput, render
from mfsample.render.settings import RenderSettings
from mfsample.render.tiles import TileStats

__all__ = ["RenderOutput", "RenderSettings", "TileStats", "render"]
