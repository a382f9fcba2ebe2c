"""Datasets: posed images with the camera conventions of `mfsample.camera`; 3DGS `.ply` files.

Read: NeRF Synthetic, LLFF, COLMAP and nerfstudio captures, 3DGS `.ply` files. Written: NeRF
Synthetic, COLMAP and nerfstudio captures, 3DGS `.ply` files.
"""

from mfsample.data._io import DatasetError
from mfsample.data.blender import available_splits, load_blender
from mfsample.data.colmap import PointCloud, export_colmap, load_colmap
from mfsample.data.export import export_blender
from mfsample.data.llff import load_llff, poses_bounds_from_cameras
from mfsample.data.nerfstudio import export_nerfstudio, load_nerfstudio
from mfsample.data.ply import export_ply, load_ply
from mfsample.data.views import Views

__all__ = [
    "DatasetError",
    "PointCloud",
    "Views",
    "available_splits",
    "export_blender",
    "export_colmap",
    "export_nerfstudio",
    "export_ply",
    "load_blender",
    "load_colmap",
    "load_llff",
    "load_nerfstudio",
    "load_ply",
    "poses_bounds_from_cameras",
]
