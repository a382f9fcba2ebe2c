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


def _same_views(a, b, n):
  """Whether two planning run records start with the same `n` views (candidates and poses)."""
  return (a["indices"][:n] == b["indices"][:n]
          and a["world_to_camera"][:n] == b["world_to_camera"][:n])


def reusable_rows(path, header, runs, wanted_keys):
  """Rows of another call's final-model file `path` that are models this call would train.

  Used by `benchmarks/final_training.py --reuse_rows_from`. A row qualifies when the file's
  final training, initialisation offset and judging resolution (absent: the run's) equal
  `header`'s (otherwise a ValueError: all its rows are other models), its key (strategy,
  seed, views, steps, train_seed) is in `wanted_keys`, it was trained (not read from a run
  record), and its run in the file's own results.json chose the same first `views` views as
  this call's run of that (strategy, seed) in `runs`. Each comes back marked with
  `reused_from`.
  """
  with open(path) as f:
    old = json.load(f)
  for field in ("final_train", "init_offset", "judge_resolution"):
    if old["header"].get(field) != header.get(field):
      raise ValueError(f"{path} has another {field} than this call; its rows are other models.")
  with open(old["header"]["results"]) as f:
    old_runs = {(r["strategy"], int(r["seed"])): r for r in json.load(f)["runs"]}
  mine = {(r["strategy"], int(r["seed"])): r for r in runs}
  out = []
  for row in old["rows"]:
    key = (row["strategy"], row["seed"], row["views"], row["steps"], row["train_seed"])
    run, old_run = mine.get(key[:2]), old_runs.get(key[:2])
    if (key in wanted_keys and not row["from_run_record"] and old_run is not None
        and _same_views(run, old_run, row["views"])):
      out.append({**row, "reused_from": path})
  return out
