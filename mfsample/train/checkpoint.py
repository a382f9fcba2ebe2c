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

import jax
import numpy as np

_PATTERN = re.compile(r"^ckpt_(\d+)\.npz$")


def _flatten(tree):
  leaves, _ = jax.tree_util.tree_flatten_with_path(tree)
  return {jax.tree_util.keystr(path): np.asarray(leaf) for path, leaf in leaves}


def save_checkpoint(directory, state, meta, keep=2):
  """Writes `ckpt_<step>.npz` atomically and keeps the newest `keep` checkpoints.

  Args:
    directory: folder (created if missing).
    state: a pytree (the `TrainState`).
    meta: JSON-serialisable dict; must contain "step".

  Returns:
    the path written.
  """
  os.makedirs(directory, exist_ok=True)
  step = int(meta["step"])
  arrays = _flatten(state)
  if "__meta__" in arrays:
    raise ValueError("a state leaf may not be called __meta__")
  arrays["__meta__"] = np.asarray(json.dumps(meta))
  path = os.path.join(directory, f"ckpt_{step:08d}.npz")
  tmp = path + ".tmp"
  with open(tmp, "wb") as f:
    np.savez(f, **arrays)
    f.flush()
    os.fsync(f.fileno())
  os.replace(tmp, path)
  for old in list_checkpoints(directory)[:-keep] if keep else []:
    os.remove(old)
  return path


def list_checkpoints(directory):
  """Checkpoint paths in `directory`, oldest first."""
  if not os.path.isdir(directory):
    return []
  found = [(int(m.group(1)), name) for name in os.listdir(directory)
           if (m := _PATTERN.match(name))]
  return [os.path.join(directory, name) for _, name in sorted(found)]


def read_meta(path):
  """The metadata dict of a checkpoint file."""
  with np.load(path) as data:
    return json.loads(str(data["__meta__"]))


def restore_checkpoint(path, template):
  """Fills `template`'s leaves from the checkpoint at `path`.

  Args:
    path: a checkpoint file.
    template: a pytree with the structure, shapes and dtypes of the saved state.

  Returns:
    (state, meta).

  Raises:
    ValueError: if the structure or a shape does not match.
  """
  leaves, treedef = jax.tree_util.tree_flatten_with_path(template)
  with np.load(path) as data:
    meta = json.loads(str(data["__meta__"]))
    saved = set(data.files) - {"__meta__"}
    names = [jax.tree_util.keystr(p) for p, _ in leaves]
    if saved != set(names):
      raise ValueError(f"checkpoint {path} does not match the state structure: "
                       f"missing {sorted(set(names) - saved)}, extra {sorted(saved - set(names))}")
    out = []
    for name, (_, leaf) in zip(names, leaves, strict=True):
      value = data[name]
      if value.shape != np.shape(leaf):
        raise ValueError(f"{name}: checkpoint shape {value.shape} != template {np.shape(leaf)}")
      out.append(jax.numpy.asarray(value, dtype=np.asarray(leaf).dtype))
  return jax.tree_util.tree_unflatten(treedef, out), meta
