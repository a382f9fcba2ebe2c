"""One skeleton for every experiment: validate, the resume guard, progress, atomic results.

An experiment is a `Job`: its name, the function that runs it, `run(config, workdir) ->
results`, the validator of its config, the config fields a later call on the same workdir may
change (speed, presentation, which runs to do), the entries of the workdir that hold its
results, and how its command line reports them. A job's `run` opens its workdir first:

  with jobs.open_workdir(JOB, config, workdir) as wd:   # validated, guarded; nothing written
    data = load(config)                                  # a missing dataset writes nothing
    wd.write_config()
    record = wd.read_json("runs/a.json")                 # None: absent or damaged (reported)
    ...
    wd.write_json("runs/a.json", record)                 # atomic
    return results

and `main(JOB)` is the whole absl entry point (`--config`, `--workdir`). A new experiment is
a config, a few pure functions, a `Job` and a thin main.

Several processes (`mfsample.distributed`, initialised by `main` from the environment) run
one job on one workdir, all reading it; only process 0 writes it (`Workdir.writes`: the
`Workdir` methods write nothing in the others, and a job gates its other outputs, images
and figures, on it), and only process 0 holds the lock and checks the workdir, passing
its verdict on to the others, which refuse to start with a config that differs from
process 0's.

A workdir also records the files its results were computed from (`inputs.json`: every file
the loaders read during the call, `mfsample.fingerprints`), and a result record lists the
files it points to (`Workdir.write_json(..., files=...)`). A later call stops before it
computes anything when a recorded input has changed (or computes the results again, as the
config's `data.inputs_changed` says), and reads a record back only while the files it
points to are what they were. A workdir it may not write (a read-only mount) is still read:
a call with nothing to compute returns its results; one that has to write stops, naming it.
"""

import contextlib
import dataclasses
import json
import logging
import os
import shutil
import signal
import sys
import warnings
from collections.abc import Callable

import numpy as np

from mfsample import config_record, distributed, fingerprints, interrupts
from mfsample import workdir as workdir_lib
from mfsample._json import atomic_path, write_json, write_text
from mfsample.config_checks import ConfigError, check_choice, get_field
from mfsample.data import DatasetError


@dataclasses.dataclass(frozen=True)
class Job:
  """An experiment.

  Attributes:
    name: what it is called in messages and progress bars ("camera planning").
    kind: its identifier in workdirs (`config.json` records it) and in the viewer
      ("camera_planning").
    run: (config, workdir) -> results dict (it opens the workdir with `open_workdir`).
    validate: config -> None; raises `mfsample.config_checks.ConfigError` naming the field.
    free_fields: dotted config fields that may differ between calls on one workdir.
    results: entries of the workdir (files or folders) that hold results: when one holds
      something, a call with a config that differs elsewhere is refused.
    report: optional (results, workdir) -> text that `main` prints.
    progress_field: the config's flag of the progress bars.
    inputs_field: the config's field that says what a call does when files its results
      were computed from have changed: "stop" (the default where the config lacks it) or
      "recompute" (`INPUTS_CHANGED`); free to differ between calls.
  """

  name: str
  kind: str
  run: Callable
  validate: Callable
  free_fields: tuple
  results: tuple
  report: Callable | None = None
  progress_field: str = "progress"
  inputs_field: str = "data.inputs_changed"


# What a call does when files its workdir's results were computed from have changed.
INPUTS_CHANGED = ("stop", "recompute")
# The key under which a result record lists the files it points to (`Workdir.write_json`).
FILES_KEY = "_files"


class Workdir:
  """The workdir of one call of a job: paths, atomic writes, checked reads, progress bars.

  Attributes:
    writes: whether this process writes the workdir (process 0 of a multi-process run; the
      writing methods do nothing in the others, and so should a job's own writes).
    read_only: whether the workdir may only be read (a read-only mount or folder): its
      results are read, and the first write raises `WorkdirReadOnlyError`.
  """

  def __init__(self, job: Job, config, path, *, read_only=False, recording=None,
               inputs=None):
    self.job = job
    self.config = config
    self.path = os.fspath(path)
    self.writes = distributed.is_writer()
    self.read_only = read_only
    # The files this call reads (`fingerprints.recording`), and the record of the earlier
    # calls' inputs that this call keeps beside them.
    self._recording = recording
    self._inputs = dict(inputs or {})

  def _writable(self, name):
    """Raises `WorkdirReadOnlyError` when the workdir may not be written (`name`: the entry
    this call was about to write)."""
    if self.read_only:
      raise workdir_lib.WorkdirReadOnlyError(
          f"{self.path} is read-only, and this {self.job.name} call has results to compute "
          f"and write ({name}): make it writable, or use another --workdir")

  def _write_inputs(self, *_):
    config_record.write_inputs(self.path, {**self._inputs, **self._recording.files})

  def file(self, *parts):
    """The path of an entry of the workdir."""
    return os.path.join(self.path, *parts)

  def exists(self, *parts):
    return os.path.exists(self.file(*parts))

  def write_config(self):
    """Records the config beside the results (after the guard and the data loaded), with
    the job that writes them and the package version (`config_record.WRITTEN_BY`)."""
    if not self.writes:
      return
    self._writable(config_record.CONFIG_FILE)
    os.makedirs(self.path, exist_ok=True)
    config_record.write_config(self.config, self.path,
                             {"job": self.job.kind, "name": self.job.name,
                              "mfsample": package_version()})
    if self._recording is not None:  # the inputs read so far, then each as it is read
      self._write_inputs()
      self._recording.on_new = self._write_inputs

  def write_json(self, name, obj, indent=1, files=()):
    """Writes `obj` as JSON to the entry `name`, atomically.

    Args:
      files: entries of the workdir (files or folders) that the record points to, written
        before it: their fingerprints are kept in the record (under `FILES_KEY`), and
        `read_json` reads it back only while they are what they were.
    """
    if not self.writes:
      return
    self._writable(name)
    if files:
      obj = {**obj, FILES_KEY: fingerprints.files_under(self.path, files)}
    write_json(self.file(name), obj, indent=indent)

  def write_text(self, name, text):
    if self.writes:
      self._writable(name)
      write_text(self.file(name), text)

  def read_json(self, name):
    """The JSON content of the entry `name`; None when it is absent or damaged.

    A damaged file (truncated, not JSON, not an object), or a record whose files (`files`
    of `write_json`) are missing or changed, is reported by a warning naming it, and the
    caller computes it again (its atomic rewrite replaces the damaged file).
    """
    path = self.file(name)
    if not os.path.exists(path):
      return None
    try:
      with open(path, encoding="utf-8") as f:
        value = json.load(f)
      if not isinstance(value, dict):
        raise ValueError("not a JSON object")
      pointed = value.pop(FILES_KEY, {})
      if not (isinstance(pointed, dict) and all(isinstance(v, dict)
                                                for v in pointed.values())):
        raise ValueError(f"{FILES_KEY} is not a record of files")
    except (OSError, UnicodeDecodeError, ValueError) as e:
      warnings.warn(f"{path} is damaged ({e}); it is computed again", stacklevel=2)
      return None
    changed = fingerprints.changes({self.file(p): fp for p, fp in pointed.items()})
    if changed:
      more = f" and {len(changed) - 1} more" if len(changed) > 1 else ""
      warnings.warn(f"{path} points to files that are no longer what it wrote ({changed[0]}"
                    f"{more}); it is computed again", stacklevel=2)
      return None
    return value

  def save_arrays(self, name, **arrays):
    """Writes `arrays` as a compressed .npz to the entry `name`, atomically."""
    if not self.writes:
      return
    self._writable(name)
    with atomic_path(self.file(name)) as tmp:
      np.savez_compressed(tmp, **arrays)

  def load_arrays(self, name, keys=()):
    """{key: array} of the .npz entry `name`; None when it is absent or damaged (reported by
    a warning naming it, as `read_json`), or when it lacks one of `keys`."""
    path = self.file(name)
    if not os.path.exists(path):
      return None
    try:
      with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
      missing = set(keys) - set(arrays)
      if missing:
        raise ValueError(f"missing {sorted(missing)}")
    except Exception as e:  # noqa: BLE001 - zip, zlib, header and value errors alike
      warnings.warn(f"{path} is damaged ({type(e).__name__}: {e}); it is computed again",
                    stacklevel=2)
      return None
    return arrays

  def stage(self, message):
    """Says in one line what the job does next (`job name: message`, on stderr), when the
    config's progress flag is set (by process 0): long steps without a bar are not silent."""
    from mfsample.config_checks import get_field

    if self.writes and get_field(self.config, self.job.progress_field):
      from tqdm import tqdm

      tqdm.write(f"{self.job.name}: {message}", file=sys.stderr)

  def progress(self, total, desc=None, **kwargs):
    """A tqdm progress bar, shown when the config's progress flag is set (by process 0)."""
    from mfsample.config_checks import get_field

    show = bool(self.writes and get_field(self.config, self.job.progress_field))
    if show:
      from tqdm.auto import tqdm
    else:  # tqdm.auto in a notebook without ipywidgets warns even for a hidden bar
      from tqdm import tqdm
    return tqdm(total=total, desc=desc or self.job.name, dynamic_ncols=True,
                disable=not show, **kwargs)


@dataclasses.dataclass(frozen=True)
class Budgets:
  """The render settings that sufficed for each kind of render a job makes (its purposes:
  "eval", "score", "round_lowrank", ...), None where not known yet.

  Budgets grow on overflow and are reused, so a later render of the same kind starts from a
  budget that holds it (no regrowth, no recompilation); they change no result. The record is
  immutable: whoever grows a budget returns it, and the job keeps a new record
  (`replace`); nothing is updated behind another function's back.
  """

  settings: tuple = ()  # ((purpose, RenderSettings), ...)

  def get(self, purpose, default=None):
    """The settings of `purpose`, else `default`."""
    return dict(self.settings).get(purpose, default)

  def first(self, *purposes, default=None):
    """The settings of the first of `purposes` that is known, else `default`."""
    known = dict(self.settings)
    return next((known[p] for p in purposes if known.get(p) is not None), default)

  def replace(self, **settings):
    """A copy with the settings of some purposes replaced (None values are ignored)."""
    known = dict(self.settings)
    known.update({p: v for p, v in settings.items() if v is not None})
    return Budgets(tuple(sorted(known.items())))


def package_version():
  """The installed mfsample's version (the package's own when it is not installed)."""
  from importlib import metadata

  try:
    return metadata.version("mfsample")
  except metadata.PackageNotFoundError:
    from mfsample import __version__

    return __version__


def check_workdir(job: Job, config, workdir):
  """Refuses `workdir` when it holds results of a config that differs from `config` in any
  field but `job.free_fields` (a stale config.json with no results beside it is replaced).

  Raises:
    mfsample.workdir.WorkdirError: naming the differing fields, or the unreadable config.json.
  """
  config_record.check_same_config(
      config, workdir, free_fields=job.free_fields + (job.inputs_field,),
      has_results=config_record.holds_results(workdir, *job.results),
      results=f"{job.name} results",
      remedy="use a new --workdir, or the config that made them (or remove "
             + ", ".join(os.path.join(os.fspath(workdir), r) for r in job.results)
             + " to redo them)")


def inputs_policy(job: Job, config):
  """What a call does when its workdir's inputs changed: `job.inputs_field` of `config`
  ("stop" where the config has no such field). ConfigError for another value."""
  try:
    get_field(config, job.inputs_field)
  except ConfigError:
    return "stop"
  return check_choice(config, job.inputs_field, INPUTS_CHANGED)


def check_inputs(job: Job, config, workdir, read_only=False):
  """The record of inputs a call on `workdir` keeps ({path: fingerprint}; {} when the
  workdir holds no results, or they are to be computed again).

  When a file its results were computed from has changed (`config_record.changed_inputs`),
  the call stops, or, where `job.inputs_field` says "recompute", the results
  (`job.results`) and their record are removed, with a warning naming the files.

  Raises:
    mfsample.workdir.InputsChangedError: naming every changed file and what changed.
    mfsample.workdir.WorkdirReadOnlyError: results to recompute in a read-only workdir.
    mfsample.workdir.WorkdirError: an unreadable `inputs.json`.
  """
  if not config_record.holds_results(workdir, *job.results):
    return {}
  record = config_record.read_inputs(workdir)
  changed = fingerprints.changes(record)
  if not changed:
    return record
  what = "; ".join(changed)
  if inputs_policy(job, config) == "stop":
    raise workdir_lib.InputsChangedError(
        f"{workdir} holds {job.name} results computed from files that have changed since: "
        f"{what}. Restore them, use a new --workdir, or set --config.{job.inputs_field}="
        "recompute to compute the results again")
  if read_only:
    raise workdir_lib.WorkdirReadOnlyError(
        f"{workdir} is read-only, and its {job.name} results are to be computed again "
        f"(their inputs changed: {what}): make it writable, or use another --workdir")
  warnings.warn(f"{workdir}: files its {job.name} results were computed from have changed "
                f"({what}); computing them again ({job.inputs_field} = 'recompute')",
                stacklevel=3)
  for name in (*job.results, config_record.INPUTS_FILE):
    path = os.path.join(workdir, name)
    if os.path.isdir(path):
      shutil.rmtree(path)
    elif os.path.exists(path):
      os.remove(path)
  return {}


@contextlib.contextmanager
def open_workdir(job: Job, config, workdir):
  """Validates `config`, takes the workdir's lock for the block, refuses a workdir holding
  results of another config, and checks the files they were computed from.

  Nothing is written but the lock (`workdir/.lock`, removed at the end, with the folder if
  the block leaves it empty): the job records its config (`Workdir.write_config`) once its
  data are loaded, and with it the files read so far (`inputs.json`, then each file as it
  is read). In a multi-process run every process must pass the same config; process 0 takes
  the lock and checks the workdir, and the others start only if it succeeded. A workdir that
  exists but may not be written (a read-only mount) is opened without the lock, read-only
  (`Workdir.read_only`).

  Raises:
    mfsample.config_checks.ConfigError: a field is invalid (named).
    mfsample.workdir.WorkdirBusyError: another process holds the workdir (named).
    mfsample.workdir.WorkdirError: see `check_workdir` and `check_inputs`; a workdir that
      does not exist and cannot be created (`WorkdirReadOnlyError`).
    mfsample.distributed.DistributedError: the processes' configs differ, or (in the
      others) process 0 refused the workdir.
  """
  job.validate(config)
  inputs_policy(job, config)
  distributed.check_same_everywhere(
      json.dumps(config_record.config_dict(config), sort_keys=True), f"the {job.name} config")
  if not distributed.is_writer():
    distributed.share_outcome(None)  # raises process 0's refusal
    yield Workdir(job, config, workdir)
    return
  with contextlib.ExitStack() as stack:
    read_only = False
    try:
      try:
        stack.enter_context(workdir_lib.locked(workdir, job.name))
      except workdir_lib.WorkdirReadOnlyError:
        if not os.path.isdir(workdir):
          raise
        read_only = True  # nobody can write it: its results may be read without the lock
      check_workdir(job, config, workdir)
      kept = check_inputs(job, config, workdir, read_only)
    except Exception as e:
      distributed.share_outcome(e)
      raise
    distributed.share_outcome(None)
    recording = stack.enter_context(fingerprints.recording())
    yield Workdir(job, config, workdir, read_only=read_only, recording=recording,
                  inputs=kept)


def table_report(results, workdir):
  """A job's report when it writes `table.md`: the table and the call's wall-clock."""
  with open(os.path.join(workdir, "table.md"), encoding="utf-8") as f:
    table = f.read()
  return f"{table}\nwall-clock of this call: {results['seconds_this_call']:.0f} s"


def main(job: Job):
  """The absl entry point of `job`: `--config` (an ml_collections config file, with
  `:variant` and `--config.field=value` overrides) and `--workdir`."""
  from absl import app, flags
  from ml_collections import config_flags

  config_flag = config_flags.DEFINE_config_file("config", None, f"The {job.name} config file.",
                                                lock_config=True)
  workdir_flag = flags.DEFINE_string("workdir", None, "Output directory.")
  verbose_flag = flags.DEFINE_bool("verbose", False, "Show the traceback of an error in the "
                                   "input (config, data, workdir) after its one-line message.")
  flags.mark_flags_as_required(["config", "workdir"])
  # JAX reports at INFO each platform it probes and does not find ("Unable to initialize
  # backend 'tpu'"), which reads like an error; its warnings still show.
  logging.getLogger("jax._src.xla_bridge").setLevel(logging.WARNING)
  # A warning is one line that names the job (not the source line that issued it), and so
  # is a log line of the package (a capture's images_N/ made, ...).
  warnings.formatwarning = lambda message, category, *_, **__: (
      f"{job.name}: {category.__name__}: {message}\n")
  plain = logging.StreamHandler(sys.stderr)
  plain.setFormatter(logging.Formatter(f"{job.name}: %(message)s"))
  logging.getLogger("mfsample").addHandler(plain)
  logging.getLogger("mfsample").propagate = False  # (not again in absl's format)

  def run(argv):
    if len(argv) > 1:
      raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
    try:  # before anything runs on a device
      distributed.initialize_from_environment()
    except distributed.DistributedError as e:
      print(f"{job.name}: {e}", file=sys.stderr)
      sys.exit(2)
    workdir = workdir_flag.value
    resume = f"run the same command again to resume (the workdir {workdir} keeps the work done)"
    if distributed.is_writer() and _shows_progress(job, config_flag.value):
      print(f"{job.name}: starting (workdir {workdir})", file=sys.stderr, flush=True)

    def on_request(signum):
      name = signal.Signals(signum).name
      print(f"\n{job.name}: stopping after the current step ({name}; Ctrl-C again to stop "
            "at once)", file=sys.stderr, flush=True)

    try:
      with interrupts.stop_at_safe_points(on_request):
        results = job.run(config_flag.value, workdir)
    except interrupts.Interrupted as e:
      print(f"{job.name}: {e}; {resume}.", file=sys.stderr)
      sys.exit(e.exit_code)
    except KeyboardInterrupt:
      print(f"{job.name}: interrupted; {resume}: what was finished is kept.", file=sys.stderr)
      sys.exit(130)
    except USER_ERRORS as e:
      if verbose_flag.value:
        raise
      print(f"{job.name}: {type(e).__name__}: {e} (--verbose shows the traceback)",
            file=sys.stderr)
      sys.exit(2)
    if job.report is not None and distributed.is_writer():  # (it reads what process 0 wrote)
      print(job.report(results, workdir))

  app.run(run)


def _shows_progress(job, config):
  from mfsample.config_checks import get_field

  try:
    return bool(get_field(config, job.progress_field))
  except ConfigError:  # (reported by the job's validator)
    return False


# Errors in the user's input whose message says all (the file, the field): `main` prints it
# in one line, the traceback only with --verbose. A missing file is one (the loaders' and
# the validators' messages name it and the config field).
USER_ERRORS = (ConfigError, DatasetError, FileNotFoundError, workdir_lib.WorkdirError,
               workdir_lib.WorkdirBusyError, distributed.DistributedError)
