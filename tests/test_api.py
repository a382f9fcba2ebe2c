"""The public API fits on one screen and everything in it is documented."""

import inspect

import mfsample


def test_exports_exist_and_are_documented():
  assert mfsample.__all__, "mfsample.__all__ is empty"
  for name in mfsample.__all__:
    obj = getattr(mfsample, name)
    doc = inspect.getdoc(obj)
    assert doc and len(doc) > 20, f"mfsample.{name} has no real docstring"


def test_training_api_is_documented():
  from mfsample import export_ply, metrics, samplers
  from mfsample import model as model_lib
  from mfsample import train as train_lib

  for name in train_lib.__all__:
    assert inspect.getdoc(getattr(train_lib, name)), f"mfsample.train.{name}"
  for module in (model_lib, samplers, metrics, export_ply):
    for name, obj in vars(module).items():
      if (name.startswith("_") or not callable(obj)
          or getattr(obj, "__module__", "") != module.__name__):
        continue
      assert inspect.getdoc(obj), f"{module.__name__}.{name} has no docstring"
