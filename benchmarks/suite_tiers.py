"""What a tier of the test suite exercises: line coverage, and every module touched.

  python benchmarks/suite_tiers.py                      # the fast tier, -m "not slow"
  python benchmarks/suite_tiers.py --markers=""         # the whole suite

Runs `python -m pytest -q -n 2 -m MARKERS --cov` (pytest-cov) and, apart, the package's
modules imported and nothing else, both under coverage.py. A module is *touched* by the tier
when the tier runs lines of it that importing it does not (a function body, not only its
`def` lines). Prints the tier's wall-clock, its test count, the package's line coverage and
the modules the tier leaves untouched; writes them to `--out` as JSON.
"""

import json
import os
import re
import subprocess
import sys
import tempfile
import time

from absl import app, flags

_MARKERS = flags.DEFINE_string("markers", "not slow", "pytest -m expression of the tier "
                               "(empty: every test).")
_WORKERS = flags.DEFINE_integer("workers", 2, "pytest-xdist workers (-n).")
_PATHS = flags.DEFINE_list("paths", [], "Test files or folders (default: the suite's).")
_OUT = flags.DEFINE_string("out", "workdirs/benchmarks/suite_tiers.json", "JSON written here.")

_IMPORT_ALL = """
import importlib, pkgutil, mfsample
for info in pkgutil.walk_packages(mfsample.__path__, "mfsample."):
  if not info.name.endswith("__main__"):
    importlib.import_module(info.name)
"""


def executed_lines(data_file):
  """{module path relative to the package's parent: set of executed line numbers}."""
  import coverage

  data = coverage.CoverageData(basename=data_file)
  data.read()
  out = {}
  for path in data.measured_files():
    rel = path[path.rindex(os.sep + "mfsample" + os.sep) + 1:] if (
        os.sep + "mfsample" + os.sep) in path else None
    if rel is not None:
      out[rel] = set(data.lines(path) or ())
  return out


def run(markers, workers, paths=(), root="."):
  """Measures the tier (`paths`: test files or folders, default the suite's); returns the
  record written to JSON."""
  with tempfile.TemporaryDirectory() as tmp:
    tier_data = os.path.join(tmp, "tier.coverage")
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--cov",
               "--cov-report="]
    if workers > 1:
      command += ["-n", str(workers)]
    if markers:
      command += ["-m", markers]
    command += list(paths)
    env = {**os.environ, "COVERAGE_FILE": tier_data}
    t0 = time.perf_counter()
    tier = subprocess.run(command, cwd=root, env=env, capture_output=True, text=True,
                          check=False)
    seconds = time.perf_counter() - t0
    summary = [line for line in tier.stdout.splitlines() if re.search(r"\d+ passed", line)]
    if tier.returncode != 0 or not summary:
      raise SystemExit(f"the tier failed (exit {tier.returncode}):\n{tier.stdout[-3000:]}")
    import_data = os.path.join(tmp, "import.coverage")
    importer = os.path.join(tmp, "import_all.py")
    with open(importer, "w") as f:
      f.write(_IMPORT_ALL)
    subprocess.run([sys.executable, "-m", "coverage", "run", "--source=mfsample",
                    f"--data-file={import_data}", importer], cwd=root, check=True,
                   capture_output=True)
    # (pyproject's `patch = ["subprocess"]` makes every process write a file of its own)
    for data_file in (import_data, tier_data):
      subprocess.run([sys.executable, "-m", "coverage", "combine", "--keep", "--append",
                      f"--data-file={data_file}", *_parts(tmp, data_file)], cwd=root,
                     check=False, capture_output=True)
    tier_lines, import_lines = executed_lines(tier_data), executed_lines(import_data)
    report = subprocess.run([sys.executable, "-m", "coverage", "report", "--precision=2",
                             f"--data-file={tier_data}", "--format=total"], cwd=root,
                            capture_output=True, text=True, check=True)
  untouched = sorted(m for m, lines in import_lines.items()
                     if not tier_lines.get(m, set()) - lines and not m.endswith("__main__.py")
                     and len(lines) > 0 and not _only_definitions(os.path.join(root, m)))
  return {"markers": markers, "workers": workers, "seconds": round(seconds, 1),
          "tests": summary[-1].strip(), "line_coverage_percent": float(report.stdout.strip()),
          "modules": len(import_lines), "untouched_modules": untouched}


def _parts(folder, data_file):
  """The per-process data files of `data_file` in `folder` (`data_file.SUFFIX`)."""
  stem = os.path.basename(data_file) + "."
  return [os.path.join(folder, n) for n in os.listdir(folder) if n.startswith(stem)]


def _only_definitions(path):
  """True for a module with no function or method to run (constants and re-exports): its
  import is all there is to touch."""
  with open(path) as f:
    return not re.search(r"^\s*def ", f.read(), flags=re.M)


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
  record = run(_MARKERS.value, _WORKERS.value, _PATHS.value)
  os.makedirs(os.path.dirname(_OUT.value) or ".", exist_ok=True)
  with open(_OUT.value, "w") as f:
    json.dump(record, f, indent=2)
  print(f"tier -m {record['markers']!r}: {record['tests']}, {record['seconds']} s wall "
        f"with coverage, line coverage {record['line_coverage_percent']:.1f}%")
  print(f"modules untouched beyond their import: {len(record['untouched_modules'])} of "
        f"{record['modules']}" + "".join(f"\n  {m}" for m in record["untouched_modules"]))
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
