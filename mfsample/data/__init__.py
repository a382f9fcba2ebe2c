"""Datasets: posed images with the camera conventions of `mfsample.camera`."""

from mfsample.data._io import DatasetError
from mfsample.data.blender import available_splits, load_blender
from mfsample.data.export import export_blender
from mfsample.data.llff import load_llff, poses_bounds_from_cameras
from mfsample.data.views import Views

__all__ = [
    "DatasetError",
    "Views",
    "available_splits",
    "export_blender",
    "load_blender",
    "load_llff",
    "poses_bounds_from_cameras",
]
