"""The package's public API exists and is documented (STYLE.md: the API on one screen)."""

import inspect

import mfsample
from mfsample import export_ply, metrics, samplers
from mfsample import model as model_lib
from mfsample import train as train_lib


def test_exports_exist_and_are_documented():
  for name in mfsample.__all__:
    obj = getattr(mfsample, name)
    assert inspect.getdoc(obj), f"mfsample.{name} has no docstring"
  for name in train_lib.__all__:
    assert inspect.getdoc(getattr(train_lib, name)), f"mfsample.train.{name}"


def test_public_functions_of_the_training_modules_are_documented():
  for module in (model_lib, samplers, metrics, export_ply):
    for name, obj in vars(module).items():
      if name.startswith("_") or not callable(obj) or getattr(obj, "__module__", "") != \
          module.__name__:
        continue
      assert inspect.getdoc(obj), f"{module.__name__}.{name} has no docstring"
