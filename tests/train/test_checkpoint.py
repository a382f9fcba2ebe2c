"""Tests of mfsample.train.checkpoint: atomic writes, round trip, structure checks."""

import os

import jax.numpy as jnp
import numpy as np
import pytest

from mfsample.train import checkpoint as ckpt


def _state(scale=1.0):
  return {"step": jnp.int32(3), "params": {"a": jnp.arange(6.0).reshape(2, 3) * scale,
                                           "b": jnp.ones((4,), jnp.int8)},
          "key": jnp.asarray([1, 2], jnp.uint32)}


def test_round_trip_and_keep(tmp_path):
  d = str(tmp_path)
  for step in (5, 10, 15):
    ckpt.save_checkpoint(d, _state(step), {"step": step, "budget": 1024}, keep=2)
  paths = ckpt.list_checkpoints(d)
  assert [os.path.basename(p) for p in paths] == ["ckpt_00000010.npz", "ckpt_00000015.npz"]
  assert not any(name.endswith(".tmp") for name in os.listdir(d))
  state, meta = ckpt.restore_checkpoint(paths[-1], _state(0.0))
  assert meta == {"step": 15, "budget": 1024} and ckpt.read_meta(paths[-1]) == meta
  np.testing.assert_array_equal(state["params"]["a"], np.asarray(_state(15.0)["params"]["a"]))
  assert state["params"]["b"].dtype == jnp.int8 and state["key"].dtype == jnp.uint32


def test_structure_mismatch_is_an_error(tmp_path):
  d = str(tmp_path)
  path = ckpt.save_checkpoint(d, _state(), {"step": 1})
  wrong = _state()
  wrong["params"]["c"] = jnp.zeros(2)
  with pytest.raises(ValueError, match="does not match"):
    ckpt.restore_checkpoint(path, wrong)
  wrong = _state()
  wrong["params"]["a"] = jnp.zeros((3, 3))
  with pytest.raises(ValueError, match="shape"):
    ckpt.restore_checkpoint(path, wrong)
  assert ckpt.list_checkpoints(str(tmp_path / "missing")) == []
