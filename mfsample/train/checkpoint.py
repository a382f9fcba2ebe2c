"""Atomic checkpoints of a `TrainState` plus host-side metadata.

A checkpoint is one `.npz` file: every leaf of the state under its pytree path, and a JSON
string of metadata (step, capacity, render budget, seeds). It is written to a temporary
file in the same directory and renamed, so a kill at any moment leaves either the old or
the new checkpoint, never a torn one. Restoring needs a *template* state of the same
structure and capacity (the loop builds one from the config), whose leaves are replaced.

Everything random in training is a function of (seed, step) - z rows, view order, keys of
the step and of densification - so state + step is all a resumed run needs to continue
exactly where the killed one stopped.
"""

import json
import os
import re
import zipfile
import zlib

import jax
import numpy as np

from mfsample import distributed
from mfsample._json import atomic_path

_PATTERN = re.compile(r"^ckpt_(\d+)\.npz$")

# What reading a damaged .npz raises: a truncated or overwritten zip (BadZipFile, EOFError,
# OSError), a corrupt member (zlib.error, ValueError from numpy's header parser), a missing
# metadata entry (KeyError) or metadata that is not JSON.
READ_ERRORS = (zipfile.BadZipFile, EOFError, OSError, zlib.error, ValueError, KeyError,
               json.JSONDecodeError)


class CorruptCheckpointError(ValueError):
  """A checkpoint file that cannot be read (the message names the file and the cause)."""


def _flatten(tree):
  leaves, _ = jax.tree_util.tree_flatten_with_path(tree)
  return {jax.tree_util.keystr(path): np.asarray(leaf) for path, leaf in leaves}


def save_checkpoint(directory, state, meta, keep=2):
  """Writes `ckpt_<step>.npz` atomically and keeps the newest `keep` checkpoints.

  In a multi-process run only process 0 writes (every process holds the same state).

  Args:
    directory: folder (created if missing).
    state: a pytree (the `TrainState`).
    meta: JSON-serialisable dict; must contain "step".

  Returns:
    the path written.
  """
  if isinstance(keep, bool) or not isinstance(keep, (int, np.integer)) or keep < 1:
    raise ValueError(f"keep = {keep!r}: must be an integer >= 1 (checkpoints to keep)")
  step = int(meta["step"])
  path = os.path.join(directory, f"ckpt_{step:08d}.npz")
  if not distributed.is_writer():
    return path
  os.makedirs(directory, exist_ok=True)
  arrays = _flatten(state)
  if "__meta__" in arrays:
    raise ValueError("a state leaf may not be called __meta__")
  arrays["__meta__"] = np.asarray(json.dumps(meta))
  with atomic_path(path) as tmp, open(tmp, "wb") as f:
    np.savez(f, **arrays)
  for old in list_checkpoints(directory)[:-int(keep)]:
    os.remove(old)
  return path


def list_checkpoints(directory):
  """Checkpoint paths in `directory`, oldest first."""
  if not os.path.isdir(directory):
    return []
  found = [(int(m.group(1)), name) for name in os.listdir(directory)
           if (m := _PATTERN.match(name))]
  return [os.path.join(directory, name) for _, name in sorted(found)]


def newest_readable(directory, read):
  """The newest checkpoint in `directory` that `read` can read, and the newer ones it could not.

  Jobs resume from it (`mfsample.train.loop.restore_latest`) and the viewer shows it: a
  checkpoint cut short (a full disk, a copy interrupted) is passed over for the one before.

  Args:
    directory: a checkpoint folder.
    read: path -> value; raises `CorruptCheckpointError` for a file it cannot read. Any
      other error propagates (a readable checkpoint of another run is not passed over).

  Returns:
    (path, read(path), skipped) of the newest readable checkpoint, or (None, None, skipped)
    when there is none; skipped: (path, `CorruptCheckpointError`) of each newer one, newest
    first.
  """
  skipped = []
  for path in reversed(list_checkpoints(directory)):
    try:
      return path, read(path), skipped
    except CorruptCheckpointError as e:
      skipped.append((path, e))
  return None, None, skipped


def read_arrays(path):
  """(arrays, meta) of a checkpoint file: every saved leaf by its pytree path, and the
  metadata dict (`CorruptCheckpointError` if the file cannot be read)."""
  meta = read_meta(path)
  try:
    with np.load(path, allow_pickle=False) as data:
      arrays = {name: data[name] for name in data.files if name != "__meta__"}
  except READ_ERRORS as e:
    raise CorruptCheckpointError(f"checkpoint {path} is unreadable "
                                 f"({type(e).__name__}: {e})") from e
  return arrays, meta


def read_meta(path):
  """The metadata dict of a checkpoint file (`CorruptCheckpointError` if unreadable)."""
  try:
    with np.load(path, allow_pickle=False) as data:
      meta = json.loads(str(data["__meta__"]))
  except READ_ERRORS as e:
    raise CorruptCheckpointError(f"checkpoint {path} is unreadable "
                                 f"({type(e).__name__}: {e})") from e
  if not isinstance(meta, dict) or not isinstance(meta.get("step"), int):
    raise CorruptCheckpointError(f"checkpoint {path} has no valid metadata")
  return meta


def restore_checkpoint(path, template):
  """Fills `template`'s leaves from the checkpoint at `path`.

  Args:
    path: a checkpoint file.
    template: a pytree with the structure, shapes and dtypes of the saved state.

  Returns:
    (state, meta).

  Raises:
    CorruptCheckpointError: the file cannot be read.
    ValueError: if the structure or a shape does not match.
  """
  leaves, treedef = jax.tree_util.tree_flatten_with_path(template)
  names = [jax.tree_util.keystr(p) for p, _ in leaves]
  meta = read_meta(path)
  try:
    with np.load(path, allow_pickle=False) as data:
      saved = set(data.files) - {"__meta__"}
      values = {name: data[name] for name in names if name in saved}
  except READ_ERRORS as e:
    raise CorruptCheckpointError(f"checkpoint {path} is unreadable "
                                 f"({type(e).__name__}: {e})") from e
  if saved != set(names):
    raise ValueError(f"checkpoint {path} does not match the state structure: missing "
                     f"{sorted(set(names) - saved)}, extra {sorted(saved - set(names))}")
  out = []
  for name, (_, leaf) in zip(names, leaves, strict=True):
    value = values[name]
    if value.shape != np.shape(leaf):
      raise ValueError(f"checkpoint {path}: {name} has shape {value.shape}, the state "
                       f"{np.shape(leaf)}")
    out.append(jax.numpy.asarray(value, dtype=np.asarray(leaf).dtype))
  return jax.tree_util.tree_unflatten(treedef, out), meta
