"""Are two runs of a job the same? Compares every result of two workdirs, bit for bit.

  python benchmarks/compare_workdirs.py WORKDIR_A WORKDIR_B
  python benchmarks/compare_workdirs.py A B --rename=.spread=.b_hat   # arrays renamed in B

Every `.json` file of A (but `config.json`) is compared with B's leaf by leaf, and every
array of every `.npz` file exactly (`np.array_equal`; NaN equals NaN). What a run measures
about its machine rather than its results is left out: JSON keys containing one of
`--skip` (wall-clock seconds, CPU, the JAX version, paths, figure files). `--rename`
maps an array key of A to its name in B (`old=new`, a substring replacement), for runs of
versions that name a field differently. Prints the count of files compared and every
difference; exits 1 when there is one. Figures and other binary files are not compared:
they follow from the arrays and JSON.
"""

import json
import os
import sys

import numpy as np
from absl import app, flags

_SKIP = flags.DEFINE_list(
    "skip", ["seconds", "time", "cpu", "load_average", "calls", "jax_version", "_written_by",
             "figure", "path", "files"],
    "JSON keys containing one of these are not compared (machine, not results).")
_RENAME = flags.DEFINE_multi_string("rename", [], "old=new: an array key of A named new in B.")
_SHOW = flags.DEFINE_integer("show", 60, "Differences printed at most.")


def _compare_json(a, b, where, skip, out):
  """Appends to `out` every leaf of `a` and `b` that differs (keys containing `skip` aside)."""
  if isinstance(a, dict) and isinstance(b, dict):
    for key in sorted(set(a) | set(b)):
      if any(s in key for s in skip):
        continue
      if key not in a or key not in b:
        out.append(f"{where}.{key}: only in {'B' if key in b else 'A'}")
      else:
        _compare_json(a[key], b[key], f"{where}.{key}", skip, out)
  elif isinstance(a, list) and isinstance(b, list):
    if len(a) != len(b):
      out.append(f"{where}: {len(a)} entries in A, {len(b)} in B")
      return
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
      _compare_json(x, y, f"{where}[{i}]", skip, out)
  elif a != b and not (isinstance(a, float) and isinstance(b, float)
                       and np.isnan(a) and np.isnan(b)):
    out.append(f"{where}: {a!r} in A, {b!r} in B")


def _as_json(array):
  """The record a 0-d string array holds as JSON (a checkpoint's metadata), else None."""
  if array.ndim != 0 or array.dtype.kind != "U":
    return None
  try:
    return json.loads(str(array))
  except ValueError:
    return None


def _compare_npz(path_a, path_b, where, skip, renames, out):
  """Appends to `out` every array of `path_a` missing from `path_b` or not equal to it; a
  JSON record stored as a string array is compared as JSON."""
  with np.load(path_a) as a, np.load(path_b) as b:
    for key in a.files:
      key_b = key
      for old, new in renames:
        key_b = key_b.replace(old, new)
      if key_b not in b.files:
        out.append(f"{where}:{key}: not in B")
        continue
      x, y = a[key], b[key_b]
      record_x, record_y = _as_json(x), _as_json(y)
      if record_x is not None and record_y is not None:
        _compare_json(record_x, record_y, f"{where}:{key}", skip, out)
      elif not np.array_equal(x, y, equal_nan=x.dtype.kind in "fc" and y.dtype.kind in "fc"):
        out.append(f"{where}:{key}: differs")


def compare_workdirs(dir_a, dir_b, *, skip=(), renames=()):
  """Compares the results of two workdirs.

  Args:
    dir_a, dir_b: workdirs of one job.
    skip: JSON keys containing one of these are not compared.
    renames: (old, new) substring replacements from A's array keys to B's.

  Returns:
    (number of files compared, list of differences as lines).
  """
  out, compared = [], 0
  for root, _, files in os.walk(dir_a):
    for name in sorted(files):
      path_a = os.path.join(root, name)
      rel = os.path.relpath(path_a, dir_a)
      path_b = os.path.join(dir_b, rel)
      if not (name.endswith(".npz") or name.endswith(".json")) or name == "config.json":
        continue
      if not os.path.exists(path_b):
        out.append(f"{rel}: not in B")
        continue
      compared += 1
      if name.endswith(".json"):
        with open(path_a) as fa, open(path_b) as fb:
          _compare_json(json.load(fa), json.load(fb), rel, tuple(skip), out)
      else:
        _compare_npz(path_a, path_b, rel, tuple(skip), renames, out)
  return compared, out


def main(argv):
  if len(argv) != 3:
    raise app.UsageError("usage: compare_workdirs.py WORKDIR_A WORKDIR_B")
  for path in argv[1:]:
    if not os.path.isdir(path):
      raise app.UsageError(f"{path}: not a folder")
  renames = []
  for rename in _RENAME.value:
    old, sep, new = rename.partition("=")
    if not sep or not old:
      raise app.UsageError(f"--rename={rename!r}: expected old=new")
    renames.append((old, new))
  compared, differences = compare_workdirs(argv[1], argv[2], skip=_SKIP.value,
                                           renames=renames)
  print(f"{compared} files compared; {len(differences)} differences")
  for line in differences[:_SHOW.value]:
    print(" ", line)
  sys.exit(1 if differences else 0)


if __name__ == "__main__":
  app.run(main)
