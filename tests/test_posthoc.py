"""Tests of mfsample.train.posthoc: B_hat fitted to a frozen 3DGS model."""

import os

import jax
import numpy as np
import pytest
from conftest import tiny_config

from mfsample.data import DatasetError, load_ply
from mfsample.train import checkpoint as ckpt
from mfsample.train.posthoc import fit_spread, posthoc_config

STEPS = 40


def _pretrained(path, dataset, num_unseen=40):
  """A "pretrained" model as a .ply: the ground truth of the synthetic dataset (its training
  views see it and it renders them exactly: the mean sits at the optimum) and Gaussians far
  away where no training camera looks. SH degree 1 (with zero band-1 coefficients)."""
  from mfsample.data.ply import ply_arrays, raw_from_gaussians, write_ply
  from mfsample.train import data as data_lib

  syn = tiny_config().data.synthetic
  truth = data_lib.synthetic_gaussians(syn.num_gaussians, syn.seed, syn.sh_degree)
  looks = -np.asarray(dataset.train.cameras.center, np.float64)
  looks /= np.linalg.norm(looks, axis=1, keepdims=True)
  rng = np.random.default_rng(0)
  far = rng.normal(size=(4000, 3))
  far /= np.linalg.norm(far, axis=1, keepdims=True)
  # Outside every frustum: the half-diagonal of the field of view is 0.57 rad.
  far = far[np.arccos(np.clip(far @ looks.T, -1, 1)).min(axis=1) > 0.65][:num_unseen]
  assert len(far) == num_unseen
  n, m = syn.num_gaussians, num_unseen
  raw = raw_from_gaussians(truth)
  extra = {"means": 30.0 * far, "log_scales": np.full((m, 3), -1.0),
           "quats": np.tile([1.0, 0, 0, 0], (m, 1)), "opacity_logits": np.zeros(m),
           "sh_dc": np.zeros((m, 3))}
  mean = {g: np.concatenate([raw[g], extra[g]]) for g in raw}
  mean["sh_rest"] = np.zeros((n + m, 3, 3))
  write_ply(path, ply_arrays(mean))
  return path, n


def _config():
  config = tiny_config("lowrank")
  config.train.num_steps = STEPS
  config.train.checkpoint_every = 8
  config.loss.volume_every = 2
  config.loss.volume_weight = 1e-4  # the planning rounds' weight (see mfsample.planning.config)
  return config


def test_fit_keeps_the_mean_and_grows_b_hat_where_no_view_looks(tiny_dataset, tmp_path):
  path, num_seen = _pretrained(tmp_path / "model.ply", tiny_dataset)
  stored = load_ply(path)
  result = fit_spread(_config(), tiny_dataset.train, path)
  model = result.state.model
  assert int(result.state.step) == STEPS and result.train_seconds > 0
  n = len(stored["means"])
  for g, v in stored.items():  # the mean is the file's, bit for bit
    np.testing.assert_array_equal(np.asarray(model.params.mean[g])[:n], v, err_msg=g)
  assert int(model.sh_degree) == 1  # every band of the file, from the first step
  # The data term holds B_hat of the Gaussians the views see; the volume term alone acts
  # on those no view sees (the same initial entries and learning rates otherwise). Centres
  # and colours show it most (opacities of nearly opaque Gaussians barely move a pixel).
  spread = {g: np.asarray(v) for g, v in model.params.spread.items()}
  assert spread["means"][num_seen:n].mean() > 1.8 * spread["means"][:num_seen].mean()
  assert spread["sh_dc"][num_seen:n].mean() > 1.2 * spread["sh_dc"][:num_seen].mean()
  assert all(np.all(v[n:] == 0.0) for v in spread.values())  # padding never moves


def test_fit_resumes_exactly(tiny_dataset, tmp_path):
  path, _ = _pretrained(tmp_path / "model.ply", tiny_dataset)
  config = _config()
  straight = fit_spread(config, tiny_dataset.train, path)
  directory = str(tmp_path / "ckpt")
  fit_spread(config, tiny_dataset.train, path, checkpoint_dir=directory, stop_at=10)
  assert [os.path.basename(p) for p in ckpt.list_checkpoints(directory)] == \
      ["ckpt_00000008.npz"]
  resumed = fit_spread(config, tiny_dataset.train, path, checkpoint_dir=directory)
  assert int(resumed.state.step) == STEPS
  for a, b in zip(jax.tree.leaves(straight.state), jax.tree.leaves(resumed.state), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  assert [e["step"] for e in resumed.history] == [e["step"] for e in straight.history]


def test_posthoc_config_checks_before_running(tiny_dataset, tmp_path):
  path, _ = _pretrained(tmp_path / "model.ply", tiny_dataset)
  cfg = posthoc_config(_config(), path)
  assert (cfg.model.init_from, cfg.model.sh_degree, cfg.densify.stop) == ("ply", 1, 0)
  assert cfg.sampler.stochastic_until is None
  with pytest.raises(ValueError, match="deterministic"):
    posthoc_config(tiny_config("deterministic"), path)
  (tmp_path / "bad.ply").write_text("ply\nformat ascii 1.0\nelement vertex 0\nend_header\n")
  with pytest.raises(DatasetError, match="bad.ply"):
    posthoc_config(_config(), tmp_path / "bad.ply")
