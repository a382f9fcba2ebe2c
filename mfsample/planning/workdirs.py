"""A planning workdir: what it holds, and whether a later call may add runs to it.

`run_camera_planning` writes one `runs/<strategy>-seed<seed>.json` per finished run beside
the call's `config.json` and `results.json`. A later call on the same workdir loads those
runs instead of recomputing them, provided its config describes the same protocol: fields
that only choose which runs to do (seeds, strategies), how they are shown, or how fast they
go may differ; any other difference is refused with the fields named.
"""

import json
import os

from mfsample._json import without_fields
from mfsample.train.loop import SPEED_ONLY_FIELDS

# Fields that may change between calls on one workdir: which runs to do, presentation,
# and the training configs' speed-only fields (`mfsample.train.loop.SPEED_ONLY_FIELDS`).
RESUME_FREE_FIELDS = ("seeds", "strategies", "progress", "figures", "data.progress",
                      "paired_references") + tuple(
                          f"{train}.{field}" for train in ("round_train", "final_train")
                          for field in SPEED_ONLY_FIELDS)


def pool_record(pool):
  """What results.json records of the pool: scene, [width, height], candidate and test counts."""
  return {"scene": pool.name,
          "resolution": [int(pool.candidates.images.shape[2]),
                         int(pool.candidates.images.shape[1])],
          "num_candidates": len(pool.candidates), "num_test": len(pool.test)}


def comparable_config(config_dict):
  """A planning config as a JSON dict, less the fields a resumed call may change."""
  return without_fields(config_dict, RESUME_FREE_FIELDS)


def differences(old, new, prefix=""):
  """Dotted paths of the leaves where two nested dicts differ."""
  if not (isinstance(old, dict) and isinstance(new, dict)):
    return [] if old == new else [prefix or "(root)"]
  out = []
  for key in sorted(set(old) | set(new)):
    path = f"{prefix}.{key}" if prefix else key
    if key not in old or key not in new:
      out.append(path)
    else:
      out += differences(old[key], new[key], path)
  return out


def run_name(strategy, seed):
  """A run's file name in `runs/` (without `.json`)."""
  return f"{strategy}-seed{seed}"


def check_resumable(config, workdir):
  """Refuses to add runs to a workdir whose finished runs used a different protocol."""
  path = os.path.join(workdir, "config.json")
  runs = os.path.join(workdir, "runs")
  if not os.path.exists(path) or not (os.path.isdir(runs) and os.listdir(runs)):
    return
  with open(path) as f:
    old = comparable_config(json.load(f))
  new = comparable_config(json.loads(config.to_json_best_effort()))
  if old != new:
    raise ValueError(f"{workdir} holds runs made with a different config (differences: "
                     f"{', '.join(differences(old, new))}); use a new --workdir, or remove "
                     f"{workdir}/runs to redo them.")
