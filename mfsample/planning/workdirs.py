"""A planning workdir: what it holds, and whether a later call may add runs to it.

`run_camera_planning` writes one `runs/<strategy>-seed<seed>.json` per finished run beside
the call's `config.json` and `results.json`. A later call on the same workdir loads those
runs instead of recomputing them, provided its config describes the same protocol (fields
that only choose which runs to do, or how fast, may differ); `restore_runs` seeds a workdir
from a committed results directory the same way; `check_run_matches` guards the scripts
that train again on a finished run's views.
"""

import json
import os
import shutil

from mfsample._json import without_fields, write_json
from mfsample.train.loop import SPEED_ONLY_FIELDS


def pool_record(pool):
  """What results.json records of the pool: scene, [width, height], candidate and test counts."""
  return {"scene": pool.name,
          "resolution": [int(pool.candidates.images.shape[2]),
                         int(pool.candidates.images.shape[1])],
          "num_candidates": len(pool.candidates), "num_test": len(pool.test)}


def check_run_matches(pool, results, *, any_resolution=False):
  """Raises unless `pool` (built from a config) is the pool of a finished run (`results.json`).

  Compared on the pool itself, not on config fields: a blender scene's size comes from its
  files and `data.downscale`, not from `data.width` / `data.height`. `any_resolution`
  accepts the same scene and views at another image size (the run's views judged at another
  resolution: candidates are kept by index, new poses are captured again at that size).
  """
  have = pool_record(pool)
  differ = [f"{key} {have[key]} (the run's {results.get(key)})" for key in have
            if key in results and have[key] != results[key]
            and not (any_resolution and key == "resolution")]
  if differ:
    raise ValueError("the config's pool differs from the run's: " + ", ".join(differ)
                     + "; pass the config the run was made with.")


# Fields that may change between calls on one workdir: which runs to do, presentation,
# and the training configs' speed-only fields (`mfsample.train.loop.SPEED_ONLY_FIELDS`).
_RESUME_FREE_FIELDS = ("seeds", "strategies", "progress", "figures", "data.progress",
                       "paired_references") + tuple(
                           f"{train}.{field}" for train in ("round_train", "final_train")
                           for field in SPEED_ONLY_FIELDS)


# Fields added to the planning config after workdirs were first written, each with the
# value that reproduces what runs did before the field existed: a config.json without one
# reads as having that value, so a newer mfsample can still resume an older workdir.
_ADDED_FIELDS = {"strategy.optimize.resample_z": False, "strategy.optimize.sampler": "",
                 # Read by ours_opt_best only, which no run before it could have used.
                 "strategy.optimize.best_every": 10}


def comparable_config(config_dict):
  d = json.loads(json.dumps(config_dict))
  for field, value in _ADDED_FIELDS.items():
    *parents, leaf = field.split(".")
    node = d
    for p in parents:
      node = node.setdefault(p, {})
    node.setdefault(leaf, value)
  return without_fields(d, _RESUME_FREE_FIELDS)


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


def holds_runs(workdir):
  """Whether `workdir/runs` holds anything: finished runs of an earlier call."""
  return bool(os.listdir(os.path.join(workdir, "runs")))


def run_name(strategy, seed):
  """A run's name in `runs/<name>.json` and in `seconds.calls[*].new_runs`."""
  return f"{strategy}-seed{seed}"


def _check_same_protocol(workdir, config_dict, than="", advice=""):
  """Refuses `config_dict` (a config as JSON) where `workdir`'s finished runs used another."""
  path = os.path.join(workdir, "config.json")
  if not os.path.exists(path) or not holds_runs(workdir):
    return
  with open(path) as f:
    old = comparable_config(json.load(f))
  new = comparable_config(config_dict)
  if old != new:
    raise ValueError(f"{workdir} holds runs made with a different config{than} (differences: "
                     f"{', '.join(differences(old, new))}){advice}")


def check_resumable(config, workdir):
  """Refuses to add runs to a workdir whose finished runs used a different protocol."""
  _check_same_protocol(workdir, json.loads(config.to_json_best_effort()),
                       advice=f"; use a new --workdir, or remove {workdir}/runs to redo them.")


def earlier_calls(workdir):
  """The wall-clock of the earlier calls on `workdir`, oldest first, from its results.json.

  Each entry is {"seconds", "new_runs"}: the call's total and the runs it computed (None
  for a results.json written before the list existed, which kept only its last call's).
  """
  path = os.path.join(workdir, "results.json")
  if not os.path.exists(path):
    return []
  with open(path) as f:
    seconds = json.load(f).get("seconds", {})
  if "calls" in seconds:
    return list(seconds["calls"])
  return [{"seconds": float(seconds["total_this_call"]), "new_runs": None}]


def restore_runs(results_dir, workdir):
  """Seeds `workdir` with the finished runs of a results directory (e.g. a committed one).

  Writes `runs/<strategy>-seed<seed>.json` for every run in `results_dir/results.json`
  that the workdir lacks, and, where the workdir holds no runs yet, its `config.json` and
  `results.json` (replacing stale ones), so the restored runs' wall-clock stays in
  `seconds.calls` (restoring from a second directory adds its calls that the workdir's
  list lacks). A later `run_camera_planning` on the workdir then loads those runs instead
  of recomputing them, and refuses, as for any resumed workdir, a config whose protocol
  differs from theirs.

  Returns:
    the names (`<strategy>-seed<seed>`) of the runs written.
  """
  paths = {name: os.path.join(results_dir, name) for name in ("results.json", "config.json")}
  for path in paths.values():
    if not os.path.exists(path):
      raise FileNotFoundError(f"cannot restore runs: {path} does not exist")
  os.makedirs(os.path.join(workdir, "runs"), exist_ok=True)
  had_runs = holds_runs(workdir)
  with open(paths["config.json"]) as f:
    _check_same_protocol(workdir, json.load(f), than=f" than {results_dir}'s")
  with open(paths["results.json"]) as f:
    results = json.load(f)
  written = []
  for record in results["runs"]:
    name = run_name(record["strategy"], record["seed"])
    path = os.path.join(workdir, "runs", f"{name}.json")
    if not os.path.exists(path):
      write_json(path, record, indent=1)
      written.append(name)
  for name, path in paths.items():
    # A workdir without runs has nothing its own config.json or results.json describes.
    if not had_runs or not os.path.exists(os.path.join(workdir, name)):
      shutil.copyfile(path, os.path.join(workdir, name))
    elif name == "results.json" and written:
      with open(os.path.join(workdir, name)) as f:
        ours_results = json.load(f)
      calls = earlier_calls(workdir)
      calls += [c for c in earlier_calls(results_dir) if c not in calls]
      ours_results.setdefault("seconds", {})["calls"] = calls
      write_json(os.path.join(workdir, name), ours_results, indent=1)
  return written
