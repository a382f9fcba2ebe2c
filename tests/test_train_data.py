"""Tests of mfsample.train.data: the dataset dispatch on config.data.kind."""

import numpy as np
import pytest
from conftest import tiny_config

from mfsample.train import data as data_lib


def test_synthetic_dataset(tiny_dataset):
  ds = tiny_dataset
  assert ds.train.images.shape == (12, 32, 32, 3) and len(ds.test) == 4
  assert float(np.min(ds.train.images)) >= 0.0 and float(np.max(ds.train.images)) <= 1.0
  assert float(np.mean(ds.train.alphas)) > 0.05  # the Gaussians are in view
  np.testing.assert_allclose(ds.bounds[0], -0.8)


def test_blender_without_data_fails_clearly(tmp_path):
  config = tiny_config()
  config.data.kind = "blender"
  config.data.path = str(tmp_path / "no_such_scene")
  with pytest.raises(FileNotFoundError, match="transforms_train.json"):
    data_lib.load_dataset(config.data)


def test_relative_paths_resolve_against_the_working_directory(tmp_path, monkeypatch):
  monkeypatch.chdir(tmp_path)
  assert data_lib.resolve_path("scene") == tmp_path.resolve() / "scene"
  assert str(data_lib.resolve_path("/abs/path")) == "/abs/path"


def test_unknown_kind_is_an_error():
  config = tiny_config()
  config.data.kind = "nerf"
  with pytest.raises(ValueError, match="config.data.kind"):
    data_lib.load_dataset(config.data)


def test_scene_kind_captures_with_the_scene_api(tmp_path):
  scenes = pytest.importorskip("mfsample.scenes")
  if not scenes.mitsuba_available():
    pytest.skip("Mitsuba (optional extra 'scenes') is not installed")
  config = tiny_config()
  config.data.kind = "scene"
  config.data.update(width=16, height=16, num_train=2, num_test=1, spp=4,
                     cache_dir=str(tmp_path))
  ds = data_lib.load_dataset(config.data)
  assert ds.train.images.shape == (2, 16, 16, 3) and len(ds.test) == 1
  scene = scenes.get_scene(config.data.scene)
  np.testing.assert_allclose(ds.bounds[1], np.asarray(scene.center) + scene.radius)


def test_scene_extent_follows_3dgs():
  import jax.numpy as jnp

  from mfsample.camera import Camera
  eyes = jnp.array([[2.0, 0, 0], [-2.0, 0, 0]])
  cams = Camera.look_at(eyes, jnp.zeros((2, 3)), jnp.array([0.0, 0, 1]), 0.8, 8, 8)
  assert data_lib.scene_extent(cams) == pytest.approx(2.2)
  assert data_lib.scene_extent(cams[:1]) == pytest.approx(2.2)  # one camera: its distance
