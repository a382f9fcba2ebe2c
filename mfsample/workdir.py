"""The resume guard shared by the experiments: a workdir holds the results of one config.

An experiment writes its config as `config.json` beside its results. A later call on the
same workdir (to resume a killed run, or to add seeds) compares its own config with that
file and refuses, naming the differing fields, when they differ in anything but the fields
the experiment declares free (speed, presentation, which runs to do). So results made with
different configs never end up in one table, and nothing is overwritten by mistake.

  check_same_config(config, workdir, free_fields=...,
                    has_results=holds_results(workdir, "runs"))  # before any write
  write_config(config, workdir)                                        # then record it
"""

import json
import os

from mfsample._json import without_fields, write_text

CONFIG_FILE = "config.json"


class WorkdirError(ValueError):
  """A workdir holds results of a different (or unknown) config."""


def config_dict(config):
  """A ConfigDict (or a plain dict) as a JSON dict: what `config.json` holds."""
  if isinstance(config, dict):
    return json.loads(json.dumps(config))
  return json.loads(config.to_json_best_effort())


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
  old = without_fields(old, free_fields)
  new = without_fields(config_dict(config), free_fields)
  if old != new:
    raise WorkdirError(f"{workdir} holds {results} made with a different config "
                       f"(differences: {', '.join(differences(old, new))}); {remedy}.")


def write_config(config, workdir):
  """Writes `workdir/config.json` atomically (after `check_same_config`)."""
  write_text(os.path.join(workdir, CONFIG_FILE), config.to_json_best_effort(indent=2))
