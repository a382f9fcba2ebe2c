"""Tests of mfsample.train.posthoc: B_hat fitted to a frozen 3DGS model.

The capture and the configuration are those of docs/your_data.md's example
(`testing.write_tiny_capture`, the default training config, 100 steps), so the example run
by tests/test_readme.py reuses this file's compiled step.
"""

import os

import jax
import numpy as np
import pytest

import mfsample as mf
from mfsample.data import DatasetError, load_colmap, load_ply
from mfsample.data.ply import ply_arrays, raw_from_gaussians, write_ply
from mfsample.train import checkpoint as ckpt
from mfsample.train.posthoc import POSTHOC_VOLUME_WEIGHT, fit_spread, posthoc_config

STEPS = 100
NUM_UNSEEN = 40


def _config():
  config = mf.train.default_config()
  config.train.num_steps = STEPS
  config.train.checkpoint_every = 40
  config.train.progress = False
  return config


@pytest.fixture(scope="module")
def pretrained(tmp_path_factory):
  """The tiny capture, and as the "pretrained" model the Gaussians that rendered it (the mean
  sits at the optimum) plus Gaussians far away where no camera looks, SH degree 1 (zero
  band-1 coefficients): the shapes of the docs' example (capacity 256)."""
  from mfsample.data import synthetic

  root = tmp_path_factory.mktemp("pretrained")
  capture, _ = mf.testing.write_tiny_capture(root)
  views, _ = load_colmap(capture)
  looks = -np.asarray(views.cameras.center, np.float64)
  looks /= np.linalg.norm(looks, axis=1, keepdims=True)
  far = np.random.default_rng(0).normal(size=(4000, 3))
  far /= np.linalg.norm(far, axis=1, keepdims=True)
  # Outside every frustum: the half-diagonal of the field of view is 0.57 rad.
  far = far[np.arccos(np.clip(far @ looks.T, -1, 1)).min(axis=1) > 0.65][:NUM_UNSEEN]
  assert len(far) == NUM_UNSEEN
  raw = raw_from_gaussians(synthetic.synthetic_gaussians(200, 0))
  m = NUM_UNSEEN
  extra = {"means": 30.0 * far, "log_scales": np.full((m, 3), -1.0),
           "quats": np.tile([1.0, 0, 0, 0], (m, 1)), "opacity_logits": np.zeros(m),
           "sh_dc": np.zeros((m, 3))}
  mean = {g: np.concatenate([raw[g], extra[g]]) for g in raw}
  mean["sh_rest"] = np.zeros((200 + m, 3, 3))
  path = write_ply(root / "model.ply", ply_arrays(mean))
  return views, path, fit_spread(_config(), views, path)


@pytest.mark.slow
def test_fit_keeps_the_mean_and_grows_b_hat_where_no_view_looks(pretrained):
  _, path, result = pretrained
  stored = load_ply(path)
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
  seen = n - NUM_UNSEEN
  assert spread["means"][seen:n].mean() > 2.0 * spread["means"][:seen].mean()
  assert spread["sh_dc"][seen:n].mean() > 2.0 * spread["sh_dc"][:seen].mean()
  assert all(np.all(v[n:] == 0.0) for v in spread.values())  # padding never moves


@pytest.mark.slow
def test_fit_resumes_exactly(pretrained, tmp_path):
  views, path, straight = pretrained
  directory = str(tmp_path / "ckpt")
  fit_spread(_config(), views, path, checkpoint_dir=directory, stop_at=50)
  assert [os.path.basename(p) for p in ckpt.list_checkpoints(directory)] == \
      ["ckpt_00000040.npz"]
  resumed = fit_spread(_config(), views, path, checkpoint_dir=directory)
  assert int(resumed.state.step) == STEPS
  for a, b in zip(jax.tree.leaves(straight.state), jax.tree.leaves(resumed.state), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  assert [e["step"] for e in resumed.history] == [e["step"] for e in straight.history]


def test_posthoc_config_checks_before_running(pretrained, tmp_path):
  _, path, _ = pretrained
  cfg = posthoc_config(_config(), path)
  assert (cfg.model.init_from, cfg.model.sh_degree, cfg.densify.stop) == ("ply", 1, 0)
  assert cfg.sampler.stochastic_until is None
  assert cfg.loss.volume_weight == POSTHOC_VOLUME_WEIGHT  # None in the config: the default
  assert cfg.loss.volume_stop_before_end == 5  # the default's 100 cut to 5% of 100 steps
  config = _config()
  config.loss.volume_weight = 0.5
  assert posthoc_config(config, path).loss.volume_weight == 0.5  # a set value is kept
  config.sampler.kind = "deterministic"
  with pytest.raises(ValueError, match="deterministic"):
    posthoc_config(config, path)
  (tmp_path / "bad.ply").write_text("ply\nformat ascii 1.0\nelement vertex 0\nend_header\n")
  with pytest.raises(DatasetError, match="bad.ply"):
    posthoc_config(_config(), tmp_path / "bad.ply")
