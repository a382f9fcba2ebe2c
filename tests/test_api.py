"""The public API fits on one screen and everything in it is documented."""

import inspect

import mfsample


def test_exports_exist_and_are_documented():
  assert mfsample.__all__, "mfsample.__all__ is empty"
  for name in mfsample.__all__:
    obj = getattr(mfsample, name)
    doc = inspect.getdoc(obj)
    assert doc and len(doc) > 20, f"mfsample.{name} has no real docstring"
