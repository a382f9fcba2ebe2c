"""Tests of mfsample.train.data: the dataset dispatch on config.data.kind."""

import numpy as np
import pytest
from conftest import tiny_config

from mfsample.data import datasets as data_lib
from mfsample.data import resolve_path


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
  assert resolve_path("scene") == tmp_path.resolve() / "scene"
  assert str(resolve_path("/abs/path")) == "/abs/path"


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


def test_llff_kind_holds_out_every_nth_view_and_boxes_the_frusta(tmp_path):
  import imageio.v3 as iio
  import jax.numpy as jnp

  from mfsample.camera import Camera
  from mfsample.data import poses_bounds_from_cameras

  eyes = np.stack([np.linspace(-1.0, 1.0, 9), np.zeros(9), np.full(9, -4.0)], -1)
  cams = Camera.look_at(jnp.asarray(eyes, jnp.float32), jnp.zeros((9, 3)),
                        jnp.array([0.0, -1.0, 0.0]), 0.8, 8, 6)
  np.save(tmp_path / "poses_bounds.npy", poses_bounds_from_cameras(cams, np.tile([1.0, 6.0],
                                                                               (9, 1))))
  (tmp_path / "images_8").mkdir()
  for v in range(9):
    iio.imwrite(tmp_path / "images_8" / f"IMG_{v}.png", np.zeros((6, 8, 3), np.uint8))
  config = tiny_config()
  config.data.kind = "llff"
  config.data.path = str(tmp_path)
  config.data.downscale = 8
  ds = data_lib.load_dataset(config.data)
  assert ds.test.names == ("IMG_0", "IMG_8") and len(ds.train) == 7 and ds.points is None
  assert np.all(ds.bounds[0] < [-1.0, -0.5, -3.0]) and np.all(ds.bounds[1] > [1.0, 0.5, 1.9])

  one = Camera.create(np.eye(4, dtype=np.float32)[None], 10.0, 10.0, 5.0, 5.0, 10, 10)
  low, high = data_lib.frustum_box(one, np.array([[1.0, 2.0]]))
  np.testing.assert_allclose(low, [-1.0, -1.0, 1.0])
  np.testing.assert_allclose(high, [1.0, 1.0, 2.0])
  with pytest.raises(ValueError, match="holdout_every = 1"):
    data_lib.holdout_split(5, 1)
