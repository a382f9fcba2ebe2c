"""The public API: every exported name exists, and no export shadows a subpackage."""

import importlib
import pkgutil

import mfsample


def test_every_export_exists():
  missing = [name for name in mfsample.__all__ if not hasattr(mfsample, name)]
  assert not missing, missing


def test_no_export_shadows_a_subpackage_or_module():
  """`mfsample.X.Y` resolves for every submodule X (e.g. `mfsample.renderer.budget`)."""
  for info in pkgutil.iter_modules(mfsample.__path__):
    if info.name.startswith("_"):
      continue
    module = importlib.import_module(f"mfsample.{info.name}")
    assert getattr(mfsample, info.name) is module, info.name
