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
