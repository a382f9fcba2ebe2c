"""Result files: JSON written whole or not at all."""

import json
import os


def write_json(path, obj, indent=2):
  """Writes `obj` to `path` as JSON, creating its folder; atomic (a temporary file renamed),
  so a run killed mid-write leaves the previous file, never a truncated one."""
  os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
  tmp = f"{path}.tmp"
  with open(tmp, "w") as f:
    json.dump(obj, f, indent=indent)
  os.replace(tmp, path)


def read_resumable_rows(path, header):
  """The rows of an earlier call that wrote `{"header": header, "rows": [...]}` to `path`,
  to resume it; [] when there is no such file. A file of another call (a different header)
  is refused rather than mixed in."""
  if not os.path.exists(path):
    return []
  with open(path) as f:
    old = json.load(f)
  if old.get("header") != header:
    raise ValueError(f"{path} was written by a call with other arguments; pass --out to "
                     "write elsewhere.")
  return old["rows"]
