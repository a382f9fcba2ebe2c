"""What camera planning decides in each round, kept for the viewer.

The planning protocol (`mfsample.planning.runner`) writes a record per finished run, with the
chosen views; the viewer also shows each round as it happens: the round model, the strategy's
score of every candidate and its choice. `record_rounds` wraps a strategy so that every call
of its `select` writes, atomically, in the workdir,

  rounds/candidates.npz                     the pool's candidate cameras (once)
  rounds/<strategy>-seed<seed>/ckpt_<V>.npz  round V (V training views): metadata (the views,
                                             the scores, the choice) and, for the first seed,
                                             the round model

in the checkpoint format (`mfsample.train.checkpoint`; the metadata's "step" is V). Models
are kept for the first seed only (that of the figures, `cameras.png` and `landscape.png`): a
round model of the default job is about 0.4 MB, and studies run up to 24 seeds.
"""

import os

import numpy as np

from mfsample._json import atomic_path
from mfsample.model import Model
from mfsample.train import checkpoint as ckpt

DIRECTORY = "rounds"
CANDIDATES = "candidates.npz"


def camera_arrays(cameras):
  """{world_to_camera [N, 4, 4], fx, fy, cx, cy [N], width, height} of a batched `Camera`."""
  return {"world_to_camera": np.asarray(cameras.world_to_camera, np.float64),
          "fx": np.asarray(cameras.fx, np.float64), "fy": np.asarray(cameras.fy, np.float64),
          "cx": np.asarray(cameras.cx, np.float64), "cy": np.asarray(cameras.cy, np.float64),
          "width": np.asarray(cameras.width), "height": np.asarray(cameras.height)}


def _write_candidates(directory, cameras):
  path = os.path.join(directory, CANDIDATES)
  if not os.path.exists(path):
    with atomic_path(path) as tmp:
      np.savez(tmp, **camera_arrays(cameras))



def _candidate_indices(train_w2c, candidate_w2c):
  """The candidate index of each training pose (None for a pose outside the pool)."""
  out = []
  for w2c in train_w2c:
    close = np.flatnonzero(np.all(np.abs(candidate_w2c - w2c) < 1e-6, axis=(1, 2)))
    out.append(int(close[0]) if close.size else None)
  return out


def round_meta(strategy, seed, inputs, choice):
  """The json-able record of one round: its views, the strategy's scores and its choice."""
  train_w2c = np.asarray(inputs.train_cameras.world_to_camera, np.float64)
  candidate_w2c = np.asarray(inputs.candidates.world_to_camera, np.float64)
  scores = choice.info.get("scores")
  meta = {
      "step": len(train_w2c), "strategy": strategy.name, "label": strategy.label,
      "seed": int(seed), "train": _candidate_indices(train_w2c, candidate_w2c),
      "train_world_to_camera": train_w2c.tolist(),
      "available": np.asarray(inputs.available, bool).tolist(),
      "chosen": {"index": None if choice.index is None else int(choice.index),
                 "world_to_camera": np.asarray(choice.camera.world_to_camera,
                                               np.float64).tolist(),
                 "score": float(choice.score)},
      "scores": None if scores is None else np.asarray(scores, np.float64).tolist(),
      "model": None,
  }
  if "trajectory" in choice.info:  # the ascent of the optimising strategies, as (u, v)
    meta["trajectory_uv"] = np.asarray(choice.info["trajectory"], np.float64).tolist()
  return meta


def record_rounds(strategy, directory, run, seed, *, keep_models, keep):
  """`strategy` whose every choice is also written to `directory` (module docstring).

  Args:
    strategy: `mfsample.planning.strategies.Strategy`.
    directory: the workdir's `rounds/` folder.
    run: the run's name (its record's in `runs/`: "<strategy>-seed<seed>").
    seed: the run's seed.
    keep_models: whether the round models are kept too (the first seed's).
    keep: rounds kept per run (the protocol's number of views: all of them).
  """
  run_dir = os.path.join(directory, run)

  def select(inputs, key):
    choice = strategy.select(inputs, key)
    _write_candidates(directory, inputs.candidates)
    meta = round_meta(strategy, seed, inputs, choice)
    model = inputs.model
    model = getattr(model, "model", model)  # ActiveNeRF's variance model wraps its mean model
    state = {}
    if keep_models and isinstance(model, Model):
      state = model
      meta["model"] = {"sampler": model.spec.to_dict()}
    ckpt.save_checkpoint(run_dir, state, meta, keep=max(int(keep), 1))
    return choice

  return strategy._replace(select=select)
