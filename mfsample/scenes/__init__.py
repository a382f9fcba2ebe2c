"""Procedural scenes and their ground-truth captures with Mitsuba 3 (optional extra `scenes`).

Scene descriptions, camera helpers and cached captures work without Mitsuba; rendering a new
capture needs it (`pip install "mfsample[scenes]"`), imported only when first used.
"""

from mfsample.scenes.cache import default_cache_dir
from mfsample.scenes.capture import (
    DEFAULT_SH_SPP,
    DEFAULT_SPP,
    Oracle,
    capture,
    capture_sh_basis,
    capture_views,
    relight,
    sh_environment_texels,
)
from mfsample.scenes.library import DEFAULT_SCENE, SCENES, get_scene
from mfsample.scenes.mitsuba_bridge import llvm_available, mitsuba_available, resolve_variant
from mfsample.scenes.scene import Lighting, Material, Scene, Shape

__all__ = [
    "DEFAULT_SCENE",
    "DEFAULT_SH_SPP",
    "DEFAULT_SPP",
    "SCENES",
    "Lighting",
    "Material",
    "Oracle",
    "Scene",
    "Shape",
    "capture",
    "capture_sh_basis",
    "capture_views",
    "default_cache_dir",
    "get_scene",
    "llvm_available",
    "mitsuba_available",
    "relight",
    "resolve_variant",
    "sh_environment_texels",
]
