"""The HTML docs build with warnings as errors, and the API reference documents every public
name of the package and of the sub-packages users import."""

import importlib
import pathlib
import re
import subprocess
import sys
import zlib

import pytest

import mfsample

ROOT = pathlib.Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "docs" / "reference"
# The sub-packages whose `__all__` the reference documents (the library's, and the jobs').
PACKAGES = ("renderer", "train", "lighting", "data", "scenes", "planning", "quality",
            "your_data", "viewer")
# Modules documented whole (every public name with a docstring).
MODULES = ("testing", "samplers", "model", "camera", "orbits", "gaussians", "view_uncertainty",
           "gaussian_uncertainty", "selection", "metrics", "sharding", "jobs", "cli",
           "baselines.fisher", "baselines.activenerf", "baselines.acp", "renderer.budget")


def _inventory(path):
  """{name: role} of the Python objects of a Sphinx `objects.inv`."""
  with open(path, "rb") as f:
    for _ in range(4):  # the header: format, project, version, compression
      f.readline()
    body = zlib.decompress(f.read()).decode()
  return dict(re.findall(r"^(\S+) (py:\w+) ", body, flags=re.MULTILINE))


def test_every_package_with_public_names_is_in_the_reference():
  """A sub-package that exports names (`__all__`) has a place in the reference."""
  exporting = {p.parent.name for p in (ROOT / "mfsample").glob("*/__init__.py")
               if "__all__" in p.read_text()}
  assert exporting == set(PACKAGES)
  text = "\n".join(p.read_text() for p in REFERENCE.glob("*.rst"))
  for name in ("", *PACKAGES, *MODULES):
    module = f"mfsample.{name}".rstrip(".")
    assert f".. automodule:: {module}\n" in text, module


@pytest.mark.slow
def test_the_docs_build_without_a_warning_and_document_every_public_name(tmp_path):
  pytest.importorskip("sphinx", reason="the docs extra: pip install -e '.[docs]'")
  pytest.importorskip("myst_parser", reason="the docs extra: pip install -e '.[docs]'")
  out = tmp_path / "html"
  build = subprocess.run(
      [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
       "-d", str(tmp_path / "doctrees"), str(ROOT / "docs"), str(out)],
      capture_output=True, text=True, timeout=900, check=False)
  assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-6000:]
  assert (out / "index.html").is_file() and (out / "reference" / "mfsample.html").is_file()
  for page in (ROOT / "docs").glob("*.md"):
    assert (out / page.with_suffix(".html").name).is_file(), page.name

  documented = _inventory(out / "objects.inv")
  # The API on one screen: each name as `mfsample.<name>`.
  for name in mfsample.__all__:
    role = "py:module" if name == "testing" else None
    assert f"mfsample.{name}" in documented, name
    assert role is None or documented[f"mfsample.{name}"] == role
  # A package's names, each under the package or, where the top level has it, there.
  for package in PACKAGES:
    module = importlib.import_module(f"mfsample.{package}")
    assert documented.get(f"mfsample.{package}") == "py:module", package
    missing = [n for n in module.__all__
               if f"mfsample.{package}.{n}" not in documented and n not in mfsample.__all__]
    assert not missing, f"mfsample.{package}: {missing}"
  for name in MODULES:
    module = importlib.import_module(f"mfsample.{name}")
    public = [n for n, v in vars(module).items()
              if not n.startswith("_") and getattr(v, "__module__", None) == module.__name__
              and callable(v) and v.__doc__]
    missing = [n for n in public if f"mfsample.{name}.{n}" not in documented
               and n not in mfsample.__all__]
    assert public and not missing, f"mfsample.{name}: {missing}"
