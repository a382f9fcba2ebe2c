"""The public API: every exported name exists, no export shadows a subpackage, and the API
page is a program that needs no config."""

import importlib
import pkgutil

import pytest

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


def test_every_exported_function_is_typed_documented_and_on_the_api_page():
  """A typed signature, a docstring with its arguments, and a row of docs/api.md."""
  import inspect
  from pathlib import Path

  page = (Path(__file__).resolve().parents[2] / "docs" / "api.md").read_text()
  problems = []
  for name in mfsample.__all__:
    obj = getattr(mfsample, name)
    if f"`{name}`" not in page:
      problems.append(f"{name}: not on docs/api.md")
    if not inspect.isfunction(obj):
      continue
    sig = inspect.signature(obj)
    untyped = [p for p, v in sig.parameters.items() if v.annotation is inspect.Parameter.empty
               and v.kind not in (v.VAR_KEYWORD, v.VAR_POSITIONAL)]
    if untyped or sig.return_annotation is inspect.Signature.empty:
      problems.append(f"{name}: untyped {untyped or 'return'}")
    doc = inspect.getdoc(obj) or ""
    if "Args:" not in doc and "Returns" not in doc and len(sig.parameters) > 2:
      problems.append(f"{name}: its docstring gives no arguments")
  assert not problems, problems


@pytest.mark.slow
def test_the_api_page_is_a_program_without_configs_or_files(tmp_path):
  """docs/api.md's code, run as one program in a fresh process: it trains a field, computes
  U, picks the next 2 of 16 views, optimises a view and picks a light, importing no
  ml_collections and writing no file. (The page's run as a docs snippet: the other pages'
  run in tests/docs/test_readme.py.)"""
  import re
  import subprocess
  import sys
  from pathlib import Path

  root = Path(__file__).resolve().parents[2]
  code = "\n".join(re.findall(r"```python\n(.*?)```", (root / "docs" / "api.md").read_text(),
                              flags=re.S))
  for name in ("mf.fit(", "mf.uncertainty(", "mf.next_views(", "mf.optimize_view(",
               "mf.next_lights("):
    assert name in code, name
  code += ("\nimport sys\nassert indices.shape == (2,) and scores.shape == (16,)"
           "\nassert not any(m.startswith('ml_collections') for m in sys.modules)\n")
  out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=tmp_path, timeout=900, check=False)
  assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-4000:]
  assert not list(tmp_path.iterdir()), "the program wrote files"
