"""The tile-based Gaussian splatting renderer, in stages."""

from mfsample.render.render import RenderOutput, render, render_jit
from mfsample.render.settings import RenderSettings
from mfsample.render.tiles import TileStats

__all__ = ["RenderOutput", "RenderSettings", "TileStats", "render", "render_jit"]
