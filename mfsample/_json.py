"""Result files written whole or not at all: JSON, text, and any writer given a path.

Every file a run writes goes through `atomic_path`: the writer fills a temporary file in the
same folder, which is flushed to disk and renamed over the target (`os.replace`, atomic on
POSIX). A run killed mid-write leaves the previous file, never a truncated one, and a writer
that raises leaves no temporary file behind.

JSON is written as the standard defines it: a number that is not finite (an undefined
statistic, a mean over nothing) becomes `null`, never the bare `NaN` / `Infinity` that Python
writes by default and that other JSON readers (browsers, jq, most languages) refuse.
"""

import contextlib
import json
import math
import os
import tempfile

import numpy as np


def _umask():
  mask = os.umask(0)
  os.umask(mask)
  return mask


# The process's file-creation mask, read once: result files get the permissions any new file
# of the user gets (os.umask can only be read by setting it).
_UMASK = _umask()


@contextlib.contextmanager
def atomic_path(path):
  """Yields a temporary path beside `path`; on success it replaces `path` atomically.

  The temporary name is unique (two writers never share one) and keeps the extension
  ("table.md" -> "table.md.x1y2.tmp.md"), so writers that choose the format by extension
  (matplotlib, imageio, numpy) write the intended format. The folder of `path` is created if
  missing. A write that fails (a full disk, a read-only folder) raises `OSError` naming
  `path`, and leaves no temporary file behind.

    with atomic_path("out/cameras.png") as tmp:
      fig.savefig(tmp)
  """
  path = os.fspath(path)
  folder = os.path.dirname(path) or "."
  try:
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=os.path.basename(path) + ".",
                               suffix=".tmp" + os.path.splitext(path)[1])
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp's 0600 would hide results from other users
  except OSError as e:
    raise OSError(e.errno, f"cannot write {path}: {e.strerror}", path) from e
  try:
    yield tmp
    with open(tmp, "rb+") as f:  # flushed before the rename: no empty file after a crash
      os.fsync(f.fileno())
    os.replace(tmp, path)
  except OSError as e:
    if e.filename not in (None, tmp):  # an error about another file: the writer's own
      raise
    raise OSError(e.errno, f"cannot write {path}: {e.strerror}", path) from e
  finally:
    if os.path.exists(tmp):
      os.remove(tmp)


@contextlib.contextmanager
def atomic_open(path, mode="w", **kwargs):
  """`open(path, mode)` whose content appears at `path` only once it is closed without error."""
  with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as f:
    yield f


def write_text(path, text):
  """Writes the string `text` to `path` atomically (UTF-8)."""
  with atomic_open(path, "w", encoding="utf-8") as f:
    f.write(text)


def finite_or_none(obj):
  """`obj` with every non-finite float (NaN, +-inf; Python or numpy) replaced by None, in
  dicts, lists and tuples at any depth; numpy scalars become Python numbers. Other values are
  returned as they are (json.dumps refuses what it cannot write)."""
  if isinstance(obj, dict):
    return {key: finite_or_none(value) for key, value in obj.items()}
  if isinstance(obj, (list, tuple)):
    return [finite_or_none(value) for value in obj]
  if isinstance(obj, np.generic) and not isinstance(obj, (np.str_, np.bytes_)):
    obj = obj.item()
  if isinstance(obj, float) and not math.isfinite(obj):
    return None
  return obj


def to_json(obj, indent=2):
  """Standard JSON text of `obj`: non-finite numbers written as null (`finite_or_none`)."""
  return json.dumps(finite_or_none(obj), indent=indent, allow_nan=False)


def write_json(path, obj, indent=2):
  """Writes `obj` to `path` as standard JSON (`to_json`: NaN and infinities become null),
  creating its folder; atomic (a temporary file renamed), so a run killed mid-write leaves
  the previous file, never a truncated one."""
  write_text(path, to_json(obj, indent=indent))


def without_fields(d, dotted_fields):
  """A deep copy of the JSON dict `d` less the leaves named by `dotted_fields` ("a.b.c");
  names that `d` lacks are ignored."""
  d = json.loads(json.dumps(d))
  for field in dotted_fields:
    *parents, leaf = field.split(".")
    node = d
    for p in parents:
      node = node.get(p, {})
    node.pop(leaf, None)
  return d
