"""Cameras in viewers' formats: read back with the project's loaders (and pycolmap), poses
compared exactly; the camera path in nerfstudio's reading; SuperSplat's cameras.json."""

import json

import jax.numpy as jnp
import numpy as np
import pytest

from mfsample.camera import Camera
from mfsample.data import load_nerfstudio
from mfsample.data.camera_export import camera_path, cameras_from_poses, export_cameras
from mfsample.your_data.export import export_planned_views


def _cameras(num=3, width=40, height=30, seed=0):
  rng = np.random.default_rng(seed)
  eyes = rng.normal(size=(num, 3))
  eyes = 2.5 * eyes / np.linalg.norm(eyes, axis=1, keepdims=True)
  looks = Camera.look_at(jnp.asarray(eyes, jnp.float32), jnp.zeros((num, 3)),
                         jnp.array([0.0, 0.0, 1.0]), 0.9, width, height)
  scale = jnp.asarray(rng.uniform(0.9, 1.1, num), jnp.float32)
  return Camera.create(looks.world_to_camera, looks.fx * scale, looks.fx * scale * 1.03,
                       jnp.asarray(width / 2 + rng.uniform(-2, 2, num), jnp.float32),
                       jnp.asarray(height / 2 + rng.uniform(-2, 2, num), jnp.float32), width,
                       height)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
  root = tmp_path_factory.mktemp("views")
  cameras = _cameras()
  images = np.random.default_rng(1).uniform(size=(3, 30, 40, 3))
  maps = np.random.default_rng(2).integers(0, 255, (3, 30, 40, 3), dtype=np.uint8)
  paths = export_cameras(root, cameras, ["a 1", "b_2", "c-3"], images=images,
                         extra_images={"uncertainty": maps}, steps_per_view=4)
  return root, cameras, images, paths


def test_nerfstudio_transforms_read_back_exactly(written):
  root, cameras, images, _ = written
  views, points = load_nerfstudio(root)
  assert views.names == ("a_1", "b_2", "c-3")  # file-name safe
  order = [0, 1, 2]
  np.testing.assert_allclose(views.cameras.world_to_camera,
                             np.asarray(cameras.world_to_camera)[order], rtol=0, atol=1e-15)
  for k in ("fx", "fy", "cx", "cy"):
    np.testing.assert_array_equal(getattr(views.cameras, k), np.asarray(getattr(cameras, k))[
        order])
  np.testing.assert_allclose(views.images, np.round(images[order] * 255) / 255, atol=1e-6)
  assert len(points) == 0
  assert (root / "uncertainty" / "a_1.png").is_file()


def test_colmap_text_model_reads_back(written):
  pytest.importorskip("pycolmap")
  from mfsample.data import load_colmap

  root, cameras, _, _ = written
  views, points = load_colmap(root)  # sparse/0/*.txt and images/
  order = [0, 1, 2]
  np.testing.assert_allclose(views.cameras.world_to_camera,
                             np.asarray(cameras.world_to_camera)[order], atol=1e-6)
  for k in ("fx", "fy", "cx", "cy"):
    np.testing.assert_array_equal(getattr(views.cameras, k), np.asarray(getattr(cameras, k))[
        order])
  assert len(points) == 0 and views.names == ("a_1", "b_2", "c-3")


def test_inria_cameras_json_holds_centre_and_camera_to_world_rotation(written):
  """SuperSplat's reader: `position` the centre, column 2 of `rotation` the viewing axis."""
  root, cameras, _, _ = written
  entries = json.loads((root / "cameras.json").read_text())
  assert [e["img_name"] for e in entries] == ["a_1", "b_2", "c-3"]
  for i, e in enumerate(entries):
    np.testing.assert_allclose(e["position"], cameras.center[i], atol=1e-6)
    rot = np.asarray(e["rotation"])
    np.testing.assert_allclose(rot.T, cameras.rotation[i], atol=1e-6)
    np.testing.assert_allclose(rot[:, 2] @ (-np.asarray(cameras.center[i])),
                               np.linalg.norm(cameras.center[i]), rtol=1e-5)  # looks at 0
    assert (e["width"], e["height"], e["fx"]) == (40, 30, float(cameras.fx[i]))


def test_camera_path_passes_through_every_camera(written):
  """Read as nerfstudio's get_path_from_json does: camera_to_world reshaped (4, 4) row-major,
  focal = (render_height / 2) / tan(fov / 2)."""
  root, cameras, _, _ = written
  path = json.loads((root / "camera_path.json").read_text())
  assert path["camera_type"] == "perspective"
  assert (path["render_width"], path["render_height"]) == (40, 30)
  frames = path["camera_path"]
  assert len(frames) == 1 + 2 * 4 and len(path["keyframes"]) == 3
  assert path["seconds"] == pytest.approx(len(frames) / path["fps"])
  for i in range(3):
    for c2w, fov in ((frames[4 * i]["camera_to_world"], frames[4 * i]["fov"]),
                     (path["keyframes"][i]["matrix"], path["keyframes"][i]["fov"])):
      c2w = np.asarray(c2w).reshape(4, 4)
      w2c = np.linalg.inv(c2w @ np.diag([1.0, -1, -1, 1]))
      np.testing.assert_allclose(w2c, cameras.world_to_camera[i], atol=1e-6)
      focal = path["render_height"] / 2.0 / np.tan(np.radians(fov) / 2.0)
      np.testing.assert_allclose(focal, cameras.fy[i], rtol=1e-6)
    assert frames[4 * i]["aspect"] == pytest.approx(40 / 30)
  middle = np.asarray(frames[2]["camera_to_world"]).reshape(4, 4)
  np.testing.assert_allclose(middle[:3, :3] @ middle[:3, :3].T, np.eye(3), atol=1e-9)
  one = camera_path(cameras[0])
  assert len(one["camera_path"]) == 1 and one["seconds"] > 0


def test_planned_views_from_a_run_record(tmp_path):
  cameras = _cameras(num=2)
  record = {"world_to_camera": np.asarray(cameras.world_to_camera).tolist()}
  intrinsics = {"fx": np.asarray(cameras.fx).tolist(), "fy": np.asarray(cameras.fy).tolist(),
                "cx": np.asarray(cameras.cx).tolist(), "cy": np.asarray(cameras.cy).tolist(),
                "width": 40, "height": 30}
  np.testing.assert_array_equal(cameras_from_poses(record["world_to_camera"], intrinsics)
                                .world_to_camera, cameras.world_to_camera)
  paths = export_planned_views(tmp_path, record["world_to_camera"], intrinsics)
  frames = json.loads(paths["transforms"].read_text())["frames"]
  assert [f["file_path"] for f in frames] == ["images/view_000.png", "images/view_001.png"]
  shared = cameras_from_poses(record["world_to_camera"], {**intrinsics, "fx": 30.0})
  assert np.all(np.asarray(shared.fx) == 30.0)
  with pytest.raises(ValueError, match="distinct"):
    export_cameras(tmp_path, cameras, ["a/b", "a_b"])


def test_camera_path_in_the_world_of_a_nerfstudio_model(tmp_path):
  """dataparser_transforms.json maps the original world to the model's: a capture's camera,
  moved there (applied_transform undone first), sees every point where it saw it before."""
  from scipy.spatial.transform import Rotation

  from mfsample.data import export_nerfstudio
  from mfsample.data.camera_export import (
    nerfstudio_camera_path,
    nerfstudio_world,
    similarity_transform,
  )
  from mfsample.data.nerfstudio import NS_PROCESS_DATA_TRANSFORM
  from mfsample.data.views import Views

  cameras = _cameras(num=2)
  export_nerfstudio(tmp_path / "capture", Views(np.zeros((2, 30, 40, 3)), cameras),
                    applied_transform=NS_PROCESS_DATA_TRANSFORM)
  stored = load_nerfstudio(tmp_path / "capture")[0].cameras  # the capture's own world
  rot = Rotation.from_euler("xyz", [0.3, -0.5, 1.1]).as_matrix()
  (tmp_path / "dataparser_transforms.json").write_text(json.dumps(
      {"transform": np.concatenate([rot, [[0.2], [-1.0], [0.4]]], 1).tolist(), "scale": 0.37}))
  m = nerfstudio_world(tmp_path / "dataparser_transforms.json", tmp_path / "capture")
  moved = similarity_transform(stored, m)
  p = np.random.default_rng(3).uniform(-0.5, 0.5, (10, 3))  # points in the original world
  p_stored = p @ NS_PROCESS_DATA_TRANSFORM[:, :3].T
  p_model = 0.37 * (p @ rot.T + [0.2, -1.0, 0.4])
  for i in range(2):
    np.testing.assert_allclose(moved[i].project(jnp.asarray(p_model, jnp.float32))[0],
                               stored[i].project(jnp.asarray(p_stored, jnp.float32))[0],
                               atol=1e-3)
  np.testing.assert_allclose(moved.center, 0.37 * (np.asarray(cameras.center) @ rot.T
                                                   + [0.2, -1.0, 0.4]), atol=1e-5)
  # The same from exported views' folder to a camera path file.
  export_cameras(tmp_path / "next", stored, ["a", "b"], images=np.zeros((2, 30, 40, 3)))
  out = nerfstudio_camera_path(tmp_path / "next", tmp_path / "dataparser_transforms.json",
                               tmp_path / "capture", tmp_path / "camera_paths" / "next.json")
  first = np.asarray(json.loads(out.read_text())["camera_path"][0]["camera_to_world"])
  np.testing.assert_allclose(np.linalg.inv(first.reshape(4, 4) @ np.diag([1.0, -1, -1, 1])),
                             moved.world_to_camera[0], atol=1e-5)
