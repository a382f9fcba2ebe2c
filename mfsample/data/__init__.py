"""Datasets: posed images with the camera conventions of `mfsample.camera`; 3DGS `.ply` files.

* loaders and writers: `load_blender` / `export_blender`, `load_colmap` / `export_colmap`,
  `load_nerfstudio` / `export_nerfstudio`, `load_llff`, `load_ply` / `export_ply`;
  `camera_export` writes cameras in viewers' formats;
* `load_dataset(spec)`: the training and test views a `DataSpec` names, dispatched on
  `spec.kind` over `DATA_KINDS` (`datasets`);
* `synthetic`: random ground-truth scenes rendered by mfsample (no files).
"""

from mfsample.data._io import DatasetError, resolve_path
from mfsample.data.blender import available_splits, load_blender
from mfsample.data.colmap import PointCloud, export_colmap, load_colmap
from mfsample.data.datasets import DATA_KINDS, FILE_KINDS, Dataset, load_dataset, scene_extent
from mfsample.data.export import export_blender
from mfsample.data.llff import load_llff, poses_bounds_from_cameras
from mfsample.data.nerfstudio import export_nerfstudio, load_nerfstudio
from mfsample.data.ply import export_ply, load_ply
from mfsample.data.views import Views

__all__ = [
    "DATA_KINDS",
    "FILE_KINDS",
    "Dataset",
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
    "load_dataset",
    "load_llff",
    "load_nerfstudio",
    "load_ply",
    "poses_bounds_from_cameras",
    "resolve_path",
    "scene_extent",
]
