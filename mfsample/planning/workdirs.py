"""A planning workdir: what it holds, and whether a later call may add runs to it.

`run_camera_planning` writes one `runs/<strategy>-seed<seed>.json` per finished run beside
the call's `config.json` and `results.json`. A later call on the same workdir loads those
runs instead of recomputing them, provided its config describes the same protocol: fields
that only choose which runs to do (seeds, strategies), how they are shown, or how fast they
go may differ; any other difference is refused with the fields named.
"""

import os

from mfsample._json import without_fields
from mfsample.train.loop import SPEED_ONLY_FIELDS
from mfsample.workdir import check_same_config, differences  # noqa: F401 (re-exported)

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


def run_name(strategy, seed):
  """A run's file name in `runs/` (without `.json`)."""
  return f"{strategy}-seed{seed}"


def check_resumable(config, workdir):
  """Refuses to add runs to a workdir whose finished runs used a different protocol
  (`mfsample.workdir.WorkdirError`, a ValueError naming the differing fields)."""
  runs = os.path.join(workdir, "runs")
  has_runs = os.path.isdir(runs) and any(n.endswith(".json") for n in os.listdir(runs))
  check_same_config(config, workdir, free_fields=RESUME_FREE_FIELDS, has_results=has_runs,
                    results="runs", remedy=f"use a new --workdir, or remove {runs} to redo them")
