"""Tests of mfsample.data.datasets: one registry of data kinds, typed `DataSpec`s, and what each
kind offers (views, points, ground truth at any camera, images under any light)."""

import jax.numpy as jnp
import numpy as np
import pytest

from mfsample.camera import Camera
from mfsample.data import datasets as data_lib
from mfsample.data import resolve_path
from mfsample.data.datasets import DataSpec, SyntheticSpec

SHELL = SyntheticSpec(shape="shell", num_gaussians=60, radius=0.5, cameras="band")


def test_synthetic_dataset(tiny_dataset):
  ds = tiny_dataset
  assert ds.train.images.shape == (12, 32, 32, 3) and len(ds.test) == 4
  assert float(np.min(ds.train.images)) >= 0.0 and float(np.max(ds.train.images)) <= 1.0
  assert float(np.mean(ds.train.alphas)) > 0.05  # the Gaussians are in view
  np.testing.assert_allclose(ds.bounds[0], -0.8)  # radius 0.6 + 0.2
  assert ds.name == "synthetic" and ds.oracle is not None and ds.sphere is not None


def test_every_kind_declares_what_it_offers():
  offers = {name: kind.offers for name, kind in data_lib.DATA_KINDS.items()}
  assert offers["scene"] == offers["synthetic"] == ("depth", "masks", "oracle", "lights")
  assert offers["colmap"] == offers["nerfstudio"] == ("points",)
  assert offers["blender"] == offers["llff"] == ()
  assert data_lib.kinds_offering("lights") == ("synthetic", "scene")
  assert set(data_lib.FILE_KINDS) == {"blender", "colmap", "llff", "nerfstudio"}
  assert DataSpec(kind="colmap").offers == ("points",)


def test_the_oracle_gives_the_ground_truth_of_any_pose():
  """A synthetic "band" dataset: its views are the oracle's images at their cameras, and a new
  pose on the same sphere gets its own image (the optimising planning strategies)."""
  spec = DataSpec(kind="synthetic", width=16, height=16, num_train=3, num_test=1,
                  background=(0.0, 0.0, 0.0), synthetic=SHELL)
  ds = data_lib.load_dataset(spec)
  np.testing.assert_allclose(ds.oracle(ds.train.cameras[1]), ds.train.images[1], atol=1e-6)
  views, box = data_lib.capture_views(spec, ds.test.cameras)
  np.testing.assert_allclose(views.images, ds.test.images, atol=1e-6)
  assert views.depths is not None and views.alphas is not None
  np.testing.assert_allclose(box[1], 0.7)
  assert (ds.sphere.radius, ds.sphere.v_range) == (3.0, (0.1, 0.6))


def test_lights_come_from_the_kinds_that_offer_them():
  spec = DataSpec(kind="synthetic", width=12, height=12, num_train=2, num_test=1,
                  synthetic=SHELL)
  data = data_lib.load_light_data(spec, 4)
  assert data.train_basis.shape == (2, 4, 12, 12, 3) and data.test_basis.shape[0] == 1
  with pytest.raises(ValueError, match="'colmap' has no images under new lights"):
    data_lib.load_light_data(DataSpec(kind="colmap"), 4)
  with pytest.raises(ValueError, match="'blender' has no ground truth at new cameras"):
    data_lib.capture_views(DataSpec(kind="blender"), None)


def test_specs_check_their_fields_by_name():
  with pytest.raises(ValueError, match="DataSpec.kind must be one of"):
    DataSpec(kind="nerf")
  with pytest.raises(ValueError, match=r"DataSpec.holdout_every must be an integer >= 2"):
    DataSpec(holdout_every=1)
  with pytest.raises(ValueError, match=r"DataSpec.background must be 3 finite numbers"):
    DataSpec(background=(1.0, 2.0, 0.0))
  with pytest.raises(ValueError, match="SyntheticSpec.shape must be one of"):
    SyntheticSpec(shape="cube")
  with pytest.raises(ValueError, match="SyntheticSpec.distance must be a finite number > 0.6"):
    SyntheticSpec(distance=0.5)
  with pytest.raises(ValueError, match="spec must be a DataSpec"):
    data_lib.load_dataset({"kind": "synthetic"})


def test_blender_without_data_fails_clearly(tmp_path):
  spec = DataSpec(kind="blender", path=str(tmp_path / "no_such_scene"))
  with pytest.raises(FileNotFoundError, match="transforms_train.json"):
    data_lib.load_dataset(spec)


def test_relative_paths_resolve_against_the_working_directory(tmp_path, monkeypatch):
  monkeypatch.chdir(tmp_path)
  assert resolve_path("scene") == tmp_path.resolve() / "scene"
  assert str(resolve_path("/abs/path")) == "/abs/path"


def test_scene_kind_captures_with_the_scene_api(tmp_path):
  scenes = pytest.importorskip("mfsample.scenes")
  if not scenes.mitsuba_available():
    pytest.skip("Mitsuba (optional extra 'scenes') is not installed")
  spec = DataSpec(kind="scene", width=16, height=16, num_train=2, num_test=1, spp=4,
                  cache_dir=str(tmp_path))
  ds = data_lib.load_dataset(spec)
  assert ds.train.images.shape == (2, 16, 16, 3) and len(ds.test) == 1
  scene = scenes.get_scene(spec.scene)
  np.testing.assert_allclose(ds.bounds[1], np.asarray(scene.center) + scene.radius)
  assert ds.name == scene.name and ds.sphere.radius == scene.camera_distance
  np.testing.assert_allclose(ds.oracle(ds.train.cameras[0]), ds.train.images[0], atol=1e-6)


def test_scene_extent_follows_3dgs():
  eyes = jnp.array([[2.0, 0, 0], [-2.0, 0, 0]])
  cams = Camera.look_at(eyes, jnp.zeros((2, 3)), jnp.array([0.0, 0, 1]), 0.8, 8, 8)
  assert data_lib.scene_extent(cams) == pytest.approx(2.2)
  assert data_lib.scene_extent(cams[:1]) == pytest.approx(2.2)  # one camera: its distance


def _tripod(center, spread=0.0, num=6):
  """`num` cameras looking around a horizontal circle from `center` (float32 poses), their
  centres `spread` apart along x (a tripod head's offset)."""
  angles = np.linspace(0.0, 2 * np.pi, num, endpoint=False)
  eyes = np.asarray(center, np.float64) + np.stack([spread * (np.arange(num) % 2),
                                                    np.zeros(num), np.zeros(num)], -1)
  targets = eyes + np.stack([np.cos(angles), np.sin(angles), np.full(num, 0.2)], -1)
  return Camera.look_at(jnp.asarray(eyes, jnp.float32), jnp.asarray(targets, jnp.float32),
                        jnp.array([0.0, 0, 1]), 0.8, 8, 8)


@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e4])
def test_scene_extent_of_cameras_turning_about_one_point(scale):
  """A tripod capture (centres apart by float32 round-off alone, or by less than 1e-3 of their
  distance from the origin) has no spread to measure: 1.1 x that distance, at any scale; a
  spread above that follows 3DGS."""
  far = scale * np.array([100.0, 0.0, 0.0])
  assert data_lib.scene_extent(_tripod(far)) == pytest.approx(110.0 * scale, rel=1e-6)
  assert data_lib.scene_extent(_tripod(far, 0.05 * scale)) == pytest.approx(
      1.1 * np.linalg.norm(far + [0.025 * scale, 0, 0]), rel=1e-6)
  assert data_lib.scene_extent(_tripod(far, 0.5 * scale)) == pytest.approx(0.275 * scale,
                                                                           rel=1e-4)
  ring = Camera.look_at(jnp.asarray([[scale, 0, 0], [-scale, 0, 0], [0, scale, 0]], jnp.float32),
                        jnp.zeros((3, 3)), jnp.array([0.0, 0, 1]), 0.8, 8, 8)
  assert data_lib.scene_extent(ring) == pytest.approx(1.1 * scale * np.sqrt(10) / 3,
                                                      rel=1e-6)


def test_scene_extent_of_cameras_at_the_origin_asks_for_it():
  with pytest.raises(ValueError, match=r"the 6 camera centres all lie at the origin.*give the "
                                       r"extent .*config.data.extent"):
    data_lib.scene_extent(_tripod(np.zeros(3)))


def test_a_tripod_capture_without_points_gets_the_fallback_extent(tmp_path):
  """A nerfstudio capture of a tripod at (100, 0, 0) without points: the box around its
  cameras spans the fallback extent (110), not float round-off."""
  from mfsample.data import Views, export_nerfstudio

  cams = _tripod([100.0, 0.0, 0.0])
  export_nerfstudio(tmp_path, Views(np.zeros((6, 8, 8, 3), np.float32), cams))
  ds = data_lib.load_dataset(DataSpec(kind="nerfstudio", path=str(tmp_path), holdout_every=3))
  np.testing.assert_allclose(ds.bounds[1] - ds.bounds[0], 220.0, rtol=1e-5)
  assert data_lib.scene_extent(ds.train.cameras) == pytest.approx(110.0, rel=1e-6)


def test_llff_kind_holds_out_every_nth_view_and_boxes_the_frusta(tmp_path):
  import imageio.v3 as iio

  from mfsample.data import poses_bounds_from_cameras

  eyes = np.stack([np.linspace(-1.0, 1.0, 9), np.zeros(9), np.full(9, -4.0)], -1)
  cams = Camera.look_at(jnp.asarray(eyes, jnp.float32), jnp.zeros((9, 3)),
                        jnp.array([0.0, -1.0, 0.0]), 0.8, 8, 6)
  np.save(tmp_path / "poses_bounds.npy", poses_bounds_from_cameras(cams, np.tile([1.0, 6.0],
                                                                               (9, 1))))
  (tmp_path / "images_8").mkdir()
  for v in range(9):
    iio.imwrite(tmp_path / "images_8" / f"IMG_{v}.png", np.zeros((6, 8, 3), np.uint8))
  ds = data_lib.load_dataset(DataSpec(kind="llff", path=str(tmp_path), downscale=8))
  assert ds.test.names == ("IMG_0", "IMG_8") and len(ds.train) == 7 and ds.points is None
  assert np.all(ds.bounds[0] < [-1.0, -0.5, -3.0]) and np.all(ds.bounds[1] > [1.0, 0.5, 1.9])
  assert ds.oracle is None and ds.name == tmp_path.name

  one = Camera.create(np.eye(4, dtype=np.float32)[None], 10.0, 10.0, 5.0, 5.0, 10, 10)
  low, high = data_lib.frustum_box(one, np.array([[1.0, 2.0]]))
  np.testing.assert_allclose(low, [-1.0, -1.0, 1.0])
  np.testing.assert_allclose(high, [1.0, 1.0, 2.0])
  with pytest.raises(ValueError, match="holdout_every = 1"):
    data_lib.holdout_split(5, 1)
