"""The tests are laid out like the code: `pytest tests/<package>` runs what covers a package.

tests/<package>/ holds the tests of mfsample/<package>/, tests/core/ those of the top-level
modules (mfsample/*.py), tests/benchmarks/ those of the benchmark scripts, tests/docs/ those
of the pages, notebooks and the repository as a whole. Shared helpers (`*_testlib.py`) and
conftest.py stay at tests/; the test folders are not packages, so pytest imports every test
file by its bare name (which must then be unique).
"""

import collections
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[2]
TESTS = ROOT / "tests"
PACKAGE = ROOT / "mfsample"
OTHERS = ("core", "benchmarks", "docs")


def _subpackages():
  return sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file())


def _folders():
  """Every folder under tests/, relative to it, less caches."""
  return sorted(p.relative_to(TESTS).as_posix() for p in TESTS.rglob("*")
                if p.is_dir() and not any(part == "__pycache__" or part.startswith(".")
                                          for part in p.relative_to(TESTS).parts))


def test_no_test_file_lies_directly_in_tests():
  loose = sorted(p.name for p in TESTS.glob("test_*.py"))
  assert not loose, f"move {loose} into tests/<package>/ (or core, benchmarks, docs)"


def test_every_test_folder_is_a_package_of_mfsample_or_core_benchmarks_docs():
  allowed = set(_subpackages()) | set(OTHERS)
  assert _folders(), "no test folders found"
  strays = [f for f in _folders() if f not in allowed]
  assert not strays, f"tests/ folders that are neither a sub-package of mfsample nor one of " \
                     f"{OTHERS}: {strays}"


def test_every_subpackage_of_mfsample_has_its_tests():
  packages = _subpackages()
  assert "renderer" in packages and "data" in packages  # the walk found the package
  missing = [p for p in packages if not list((TESTS / p).glob("test_*.py"))]
  assert not missing, f"mfsample sub-packages without tests/<package>/test_*.py: {missing}"
  assert list((TESTS / "core").glob("test_*.py")), "tests/core/ holds no test file"


def test_test_file_names_are_unique_and_the_folders_are_not_packages():
  files = list(TESTS.rglob("test_*.py"))
  assert len(files) > len(_subpackages())
  counts = collections.Counter(p.name for p in files)
  assert not [n for n, c in counts.items() if c > 1], [n for n, c in counts.items() if c > 1]
  inits = sorted(p.relative_to(TESTS).as_posix() for p in TESTS.rglob("__init__.py"))
  assert not inits, f"tests/ folders are imported by bare file name, not as packages: {inits}"
