"""A workdir's `config.json` and `inputs.json`: the config and the files its results were
computed from, and the job that wrote them.

A job writes its config as `config.json` beside its results, with the job and the package
version under `WRITTEN_BY` (what the viewer reads). A later call on the same workdir (to
resume a killed run, or to add seeds) compares its own config with that file and refuses,
naming the differing fields, when they differ in anything but the fields the job declares
free (speed, presentation, which runs to do). So results made with different configs never
end up in one table, and nothing is overwritten by mistake.

  check_same_config(config, workdir, free_fields=...,
                    has_results=holds_results(workdir, "runs"))  # before any write
  write_config(config, workdir, written_by)                      # then record it

Beside it, `inputs.json` holds the fingerprints (`mfsample.fingerprints`) of every file the
results were computed from, as the run read them; `changed_inputs(workdir)` lists those that
are no longer what they were, so that a later call stops (or computes again) before it
computes anything from them.
"""

import json
import os

from mfsample import fingerprints
from mfsample._json import without_fields, write_json, write_text
from mfsample.workdir import WorkdirError, differences

CONFIG_FILE = "config.json"
INPUTS_FILE = "inputs.json"
# The key of config.json that records which job and which mfsample wrote the workdir (not a
# config field: a later call compares the rest).
WRITTEN_BY = "_written_by"


def config_dict(config):
  """A ConfigDict (or a plain dict) as a JSON dict: what `config.json` holds."""
  if isinstance(config, dict):
    return json.loads(json.dumps(config))
  return json.loads(config.to_json_best_effort())


def read_config(workdir):
  """The JSON dict of `workdir/config.json`, or None when there is none.

  Raises:
    WorkdirError: the file exists but is not a JSON object (naming the file).
  """
  path = os.path.join(workdir, CONFIG_FILE)
  if not os.path.exists(path):
    return None
  try:
    with open(path, encoding="utf-8") as f:
      old = json.load(f)
  except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
    raise WorkdirError(f"{path} is unreadable ({e}), so the config that made the results in "
                       f"{workdir} is unknown: use a new --workdir, or restore that file."
                       ) from e
  if not isinstance(old, dict):
    raise WorkdirError(f"{path} does not hold a JSON object: use a new --workdir, or restore "
                       "that file.")
  return old


def holds_results(workdir, *names):
  """Whether any of `names` in `workdir` is an existing file or a non-empty folder."""
  for name in names:
    path = os.path.join(workdir, name)
    if os.path.isfile(path) or (os.path.isdir(path) and os.listdir(path)):
      return True
  return False


def check_same_config(config, workdir, *, free_fields=(), has_results=True, results="results",
                      remedy="use a new --workdir"):
  """Refuses to write into `workdir` when it holds results of another config.

  Args:
    config: the config of this call (a ConfigDict).
    workdir: the folder.
    free_fields: dotted fields that may differ between calls (speed, presentation).
    has_results: whether `workdir` holds results that a different config would be mixed
      with (without results, a stale `config.json` is simply replaced).
    results: what those results are, in the message ("checkpoints", "runs").
    remedy: what the user may do instead, in the message.

  Raises:
    WorkdirError: naming the differing fields (or the unreadable config.json).
  """
  if not has_results:
    return
  old = read_config(workdir)
  if old is None:
    return
  old = without_fields({k: v for k, v in old.items() if k != WRITTEN_BY}, free_fields)
  new = without_fields(config_dict(config), free_fields)
  if old != new:
    raise WorkdirError(f"{workdir} holds {results} made with a different config "
                       f"(differences: {', '.join(differences(old, new))}); {remedy}.")


def write_config(config, workdir, written_by=None):
  """Writes `workdir/config.json` atomically (after `check_same_config`): the config, and
  under `WRITTEN_BY` the dict `written_by` (the job's kind and name, the package version)."""
  record = config_dict(config)
  if written_by is not None:
    record = {WRITTEN_BY: dict(written_by), **record}
  write_text(os.path.join(workdir, CONFIG_FILE), json.dumps(record, indent=2))


def read_inputs(workdir):
  """{path: fingerprint} of the files the results of `workdir` were computed from ({} when
  it records none: a workdir written before inputs were recorded).

  Raises:
    WorkdirError: `inputs.json` exists but is not such a record (naming the file).
  """
  path = os.path.join(workdir, INPUTS_FILE)
  if not os.path.exists(path):
    return {}
  try:
    with open(path, encoding="utf-8") as f:
      record = json.load(f)
    files = record["files"]
    if not (isinstance(files, dict) and all(isinstance(v, dict) for v in files.values())):
      raise ValueError("not a record of files")
  except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as e:
    raise WorkdirError(f"{path} is unreadable ({e}), so the files the results in {workdir} "
                       "were computed from are unknown: use a new --workdir, restore that "
                       "file, or remove it to take the inputs as they are now.") from e
  return files


def changed_inputs(workdir):
  """["path: what changed", ...] of the recorded inputs of `workdir` (`read_inputs`) that
  are no longer what they were ([] when none, or none recorded)."""
  return fingerprints.changes(read_inputs(workdir))


def write_inputs(workdir, files):
  """Writes `inputs.json` ({path: fingerprint} of the files read), atomically."""
  write_json(os.path.join(workdir, INPUTS_FILE), {"files": dict(sorted(files.items()))})
