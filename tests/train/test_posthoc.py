"""Tests of mfsample.train.posthoc: B_hat fitted to a frozen 3DGS model.

The capture and the settings are those of docs/your_data.md's example
(`testing.write_tiny_capture`, the default `TrainSettings`, 100 steps), so the example run
by tests/docs/test_readme.py reuses this file's compiled step.
"""

import os

import jax
import numpy as np
import pytest

import mfsample as mf
from mfsample.data import datasets, load_colmap, load_ply
from mfsample.data.ply import raw_from_gaussians, write_gaussians_ply
from mfsample.model import model_from_mean
from mfsample.train import checkpoint as ckpt
from mfsample.train.posthoc import POSTHOC_VOLUME_WEIGHT, posthoc_settings, run_b_hat_fit

STEPS = 100
NUM_UNSEEN = 40
SETTINGS = mf.TrainSettings(num_steps=STEPS)


def _field(path, views):
  """(the stochastic field whose mean is the .ply's model, the scene extent): the default
  sampler (lowrank, rank 2, every group), fresh B_hat, seed 0."""
  mean = load_ply(path)
  extent = datasets.scene_extent(views.cameras)
  spec = mf.SamplerSpec.default(tuple(mean), extent=extent)
  return model_from_mean(jax.random.key(0), mean, spec=spec,
                         init_scales=SETTINGS.b_hat_init_scales(extent)), extent


def _fit(views, path, **kwargs):
  model, extent = _field(path, views)
  return run_b_hat_fit(model, views, SETTINGS, seed=0, extent=extent, **kwargs)


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
  path = write_gaussians_ply(root / "model.ply", mean)
  return views, path, _fit(views, path)


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
  b_hat = {g: np.asarray(v) for g, v in model.params.b_hat.items()}
  seen = n - NUM_UNSEEN
  assert b_hat["means"][seen:n].mean() > 2.0 * b_hat["means"][:seen].mean()
  assert b_hat["sh_dc"][seen:n].mean() > 2.0 * b_hat["sh_dc"][:seen].mean()
  assert all(np.all(v[n:] == 0.0) for v in b_hat.values())  # padding never moves


@pytest.mark.slow
def test_fit_resumes_exactly(pretrained, tmp_path):
  views, path, straight = pretrained
  directory = str(tmp_path / "ckpt")
  _fit(views, path, checkpoint_dir=directory, checkpoint_every=40, stop_at=50)
  assert [os.path.basename(p) for p in ckpt.list_checkpoints(directory)] == \
      ["ckpt_00000040.npz"]
  resumed = _fit(views, path, checkpoint_dir=directory, checkpoint_every=40)
  assert int(resumed.state.step) == STEPS
  for a, b in zip(jax.tree.leaves(straight.state), jax.tree.leaves(resumed.state), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  assert [e["step"] for e in resumed.history] == [e["step"] for e in straight.history]


def test_the_functional_fit_is_the_recorded_one(pretrained):
  """`mf.fit_b_hat` (the API's) is `run_b_hat_fit` with the seed drawn from its key."""
  views, path, _ = pretrained
  model, extent = _field(path, views)
  settings = SETTINGS.replace(num_steps=3)
  field, history = mf.fit_b_hat(model, views, settings, key=jax.random.key(7), extent=extent)
  seed = int(jax.random.randint(jax.random.key(7), (), 0, np.iinfo(np.int32).max))
  again = run_b_hat_fit(model, views, settings, seed=seed, extent=extent)
  for a, b in zip(jax.tree.leaves(field), jax.tree.leaves(again.state.model), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  assert [e["step"] for e in history] == [3]


def test_posthoc_settings_and_checks(pretrained):
  _, path, _ = pretrained
  fitted = posthoc_settings(SETTINGS)
  assert not fitted.train_mean and fitted.sh_degree_every == 0
  assert (fitted.densify.start, fitted.densify.stop) == (0, 0)
  assert fitted.stochastic_until is None
  assert fitted.loss.volume_weight == POSTHOC_VOLUME_WEIGHT  # None in the settings: the default
  assert fitted.loss.volume_stop_before_end == 5  # the default's 100 cut to 5% of 100 steps
  kept = SETTINGS.replace(loss=SETTINGS.loss.replace(volume_weight=0.5))
  assert posthoc_settings(kept).loss.volume_weight == 0.5  # a set value is kept
  views, _, _ = pretrained
  model, _ = _field(path, views)
  plain = model.replace(spec=mf.SamplerSpec("deterministic", groups=()))
  with pytest.raises(ValueError, match="no B_hat to fit"):
    mf.fit_b_hat(plain, views, SETTINGS, key=jax.random.key(0))
