"""nerfstudio captures: round trips, ns-process-data's conventions against COLMAP's own model,
images_N, the refusals, and the data kind in training and planning."""

import json

import imageio.v3 as iio
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import tiny_config

from mfsample.camera import Camera
from mfsample.data import (
  DatasetError,
  PointCloud,
  Views,
  export_colmap,
  export_nerfstudio,
  load_colmap,
  load_nerfstudio,
)
from mfsample.data._io import area_downscale
from mfsample.data.nerfstudio import NS_PROCESS_DATA_TRANSFORM


def _views(num=4, width=32, height=24, seed=0, same_intrinsics=False):
  """Random images seen by cameras around the origin with unequal, off-centre intrinsics."""
  rng = np.random.default_rng(seed)
  eyes = rng.normal(size=(num, 3))
  eyes = 3.0 * eyes / np.linalg.norm(eyes, axis=1, keepdims=True)
  looks = Camera.look_at(jnp.asarray(eyes, jnp.float32), jnp.zeros((num, 3)),
                         jnp.array([0.0, 0.0, 1.0]), 0.8, width, height)
  scale = np.ones(num) if same_intrinsics else rng.uniform(0.9, 1.1, num)
  shift = rng.uniform(-1, 1, (1 if same_intrinsics else num, 2)) * np.ones((num, 1))
  cameras = Camera.create(looks.world_to_camera, looks.fx * scale, looks.fx * scale * 1.02,
                          jnp.asarray(width / 2 + shift[:, 0], jnp.float32),
                          jnp.asarray(height / 2 + shift[:, 1], jnp.float32), width, height)
  images = rng.uniform(size=(num, height, width, 3)).astype(np.float32)
  return Views(images, cameras, names=tuple(f"frame_{i}" for i in range(num)))


def _points(num=20, seed=1):
  rng = np.random.default_rng(seed)
  return PointCloud(rng.uniform(-1, 1, (num, 3)).astype(np.float32),
                    (rng.integers(0, 256, (num, 3)) / 255.0).astype(np.float32))


def _assert_same_cameras(a, b):
  """Intrinsics bit for bit; poses to 1e-15: every float32 entry comes back as it was, except
  that an entry of exactly 0 may come back as float64 round-off of the inversions (~1e-17)."""
  np.testing.assert_allclose(a.world_to_camera, b.world_to_camera, rtol=0, atol=1e-15)
  for field in ("fx", "fy", "cx", "cy"):
    np.testing.assert_array_equal(np.asarray(getattr(a, field)), np.asarray(getattr(b, field)),
                                  err_msg=field)
  assert (a.width, a.height) == (b.width, b.height)


@pytest.mark.parametrize("same_intrinsics", [True, False])
def test_round_trip_is_exact(tmp_path, same_intrinsics):
  views, points = _views(same_intrinsics=same_intrinsics), _points()
  export_nerfstudio(tmp_path, views, points)
  meta = json.loads((tmp_path / "transforms.json").read_text())
  assert meta["camera_model"] == "PINHOLE" and meta["ply_file_path"] == "sparse_pc.ply"
  assert ("fl_x" in meta) == same_intrinsics  # shared intrinsics at the top, else per frame
  assert ("fl_x" in meta["frames"][0]) != same_intrinsics
  back, pts = load_nerfstudio(tmp_path)
  _assert_same_cameras(back.cameras, views.cameras)
  np.testing.assert_array_equal(back.images, np.round(views.images * 255) / 255)
  assert back.names == tuple(f"0000{i}_frame_{i}" for i in range(4))
  np.testing.assert_array_equal(pts.xyz, points.xyz)
  np.testing.assert_array_equal(pts.rgb, points.rgb)
  with pytest.raises(FileExistsError):
    export_nerfstudio(tmp_path, views)


def test_opengl_axes_of_transform_matrix(tmp_path):
  """transform_matrix is camera-to-world with the camera looking down its -z and its y up."""
  views = _views(num=1)
  export_nerfstudio(tmp_path, views)
  c2w = np.asarray(json.loads((tmp_path / "transforms.json").read_text())["frames"][0][
      "transform_matrix"])
  camera = views.cameras[0]
  np.testing.assert_allclose(c2w[:3, 3], np.asarray(camera.center), atol=1e-6)
  forward = -c2w[:3, 2]  # the point the camera looks at (the origin) lies along -z
  np.testing.assert_allclose(forward, -c2w[:3, 3] / np.linalg.norm(c2w[:3, 3]), atol=1e-5)
  np.testing.assert_allclose(c2w[:3, 1], -np.asarray(camera.rotation)[1], atol=1e-6)  # y: up


def _ns_process_data(colmap_root, out, views, points):
  """transforms.json and sparse_pc.ply built from COLMAP's poses by ns-process-data's steps
  (nerfstudio/process_data/colmap_utils.py), written here by hand: c2w = inv(w2c), its y and
  z axes negated (OpenCV -> OpenGL), world rows (x, z, -y); the points through the same
  applied_transform, as an ASCII ply with 8-bit colours."""
  frames = []
  for i in range(len(views)):
    w2c = np.asarray(views.cameras.world_to_camera[i], np.float64)
    c2w = np.linalg.inv(w2c)
    c2w[0:3, 1:3] *= -1
    c2w = c2w[np.array([0, 2, 1, 3]), :]
    c2w[2, :] *= -1
    frames.append({"file_path": f"images/{views.names[i]}.png",
                   "transform_matrix": c2w.tolist(), "colmap_im_id": i + 1})
  applied = np.eye(4)[:3, :][np.array([0, 2, 1]), :]
  applied[2, :] *= -1
  cams = views.cameras
  meta = {"w": cams.width, "h": cams.height, "fl_x": float(cams.fx[0]),
          "fl_y": float(cams.fy[0]), "cx": float(cams.cx[0]), "cy": float(cams.cy[0]),
          "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "camera_model": "OPENCV",
          "frames": frames, "applied_transform": applied.tolist(),
          "ply_file_path": "sparse_pc.ply"}
  (out / "images").mkdir(parents=True)
  for i, image in enumerate(views.images):
    iio.imwrite(out / "images" / f"{views.names[i]}.png",
                np.round(np.asarray(image) * 255).astype(np.uint8))
  xyz = np.asarray(points.xyz, np.float64) @ applied[:, :3].T + applied[:, 3]
  rgb = np.round(np.asarray(points.rgb) * 255).astype(int)
  lines = ["ply", "format ascii 1.0", f"element vertex {len(xyz)}", "property float x",
           "property float y", "property float z", "property uint8 red", "property uint8 green",
           "property uint8 blue", "end_header"]
  lines += [f"{x:8f} {y:8f} {z:8f} {r} {g} {b}" for (x, y, z), (r, g, b) in zip(xyz, rgb,
                                                                                strict=True)]
  (out / "sparse_pc.ply").write_text("\n".join(lines) + "\n")
  (out / "transforms.json").write_text(json.dumps(meta, indent=4))


def test_ns_process_data_layout_matches_colmaps_model(tmp_path):
  """A capture processed the way ns-process-data does it reads back, in frame="original", as
  the COLMAP model it came from (load_colmap with pycolmap); applied_transform exactly undone."""
  pytest.importorskip("pycolmap")
  views, points = _views(same_intrinsics=True), _points()
  export_colmap(tmp_path / "colmap", views, points)
  colmap_views, colmap_points = load_colmap(tmp_path / "colmap")
  named = views.replace(names=tuple(n for n in colmap_views.names))
  _ns_process_data(tmp_path / "colmap", tmp_path / "ns", named, points)
  original, pts = load_nerfstudio(tmp_path / "ns", frame="original")
  np.testing.assert_allclose(original.cameras.world_to_camera,
                             colmap_views.cameras.world_to_camera, atol=2e-7)
  for k in ("fx", "fy", "cx", "cy"):
    np.testing.assert_array_equal(getattr(original.cameras, k), getattr(colmap_views.cameras, k))
  np.testing.assert_allclose(pts.xyz, colmap_points.xyz, atol=1e-6)  # the ASCII's 6 decimals
  np.testing.assert_array_equal(pts.rgb, colmap_points.rgb)
  np.testing.assert_array_equal(original.images, colmap_views.images)
  assert original.names == colmap_views.names
  # The file's own world: the same cameras seen through applied_transform, points alike.
  stored, stored_pts = load_nerfstudio(tmp_path / "ns")
  applied = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
  np.testing.assert_allclose(stored.cameras.center, np.asarray(original.cameras.center)
                             @ applied.T, atol=1e-6)
  np.testing.assert_allclose(stored_pts.xyz, pts.xyz @ applied.T, atol=1e-6)
  np.testing.assert_array_equal(NS_PROCESS_DATA_TRANSFORM[:, :3], applied)


def test_applied_transform_round_trip_is_exact(tmp_path):
  views, points = _views(), _points()
  export_nerfstudio(tmp_path, views, points, applied_transform=NS_PROCESS_DATA_TRANSFORM)
  original, pts = load_nerfstudio(tmp_path / "transforms.json", frame="original")
  _assert_same_cameras(original.cameras, views.cameras)
  np.testing.assert_array_equal(pts.xyz, points.xyz)


def test_images_n_scales_the_intrinsics(tmp_path):
  views = _views(width=32, height=24)
  export_nerfstudio(tmp_path, views, downscales=(2,))
  half, _ = load_nerfstudio(tmp_path, factor=2)
  assert half.images.shape == (4, 12, 16, 3)
  for k in ("fx", "fy", "cx", "cy"):
    np.testing.assert_allclose(getattr(half.cameras, k), np.asarray(getattr(views.cameras, k))
                               / 2, rtol=1e-6)
  expected = np.stack([np.round(area_downscale(im, 2) * 255) / 255 for im in views.images])
  np.testing.assert_allclose(half.images, expected, atol=1e-6)
  with pytest.raises(FileNotFoundError, match="images_4"):
    load_nerfstudio(tmp_path, factor=4, make_downscaled=False)  # (test_downscaled.py: made)


def _edit(root, change):
  meta = json.loads((root / "transforms.json").read_text())
  change(meta)
  (root / "transforms.json").write_text(json.dumps(meta))


@pytest.mark.parametrize("change, message", [
    (lambda m: m.update(k1=0.01, camera_model="OPENCV"),
     r"frame 'images/00000_frame_0.png' has the camera model 'OPENCV' with distortion"),
    (lambda m: m["frames"][1].update(p2=-0.002),
     r"frame 'images/00001_frame_1.png' has the camera model 'PINHOLE' with distortion .*p2"),
    (lambda m: m.update(camera_model="OPENCV_FISHEYE"), r"camera model 'OPENCV_FISHEYE'.*"
     "--camera-type pinhole"),
    (lambda m: m["frames"][2].update(fl_x=10.0), r"frame 'images/00002_frame_2.png' has fl_x = "
     r"10.0 but the top level says"),
    (lambda m: m.pop("fl_y"), r"'fl_y' is neither in the frame nor at the top level"),
    (lambda m: m["frames"][0].update(transform_matrix=np.diag([1.0, 1, 1, 1]).tolist()[:2]),
     r"'transform_matrix' must be a 3x4 or 4x4 matrix"),
    (lambda m: m["frames"][3].update(transform_matrix=np.diag([2.0, 1, 1, 1]).tolist()),
     r"frame 'images/00003_frame_3.png': 'transform_matrix' is not rigid"),
    (lambda m: m.update(frames=[]), r"'frames' is empty"),
])
def test_refusals_name_the_model_the_key_and_the_frame(tmp_path, change, message):
  export_nerfstudio(tmp_path, _views(same_intrinsics=True))
  load_nerfstudio(tmp_path)
  _edit(tmp_path, change)
  with pytest.raises(DatasetError, match=message):
    load_nerfstudio(tmp_path)


def test_zero_distortion_and_per_frame_values_are_read(tmp_path):
  views = _views(same_intrinsics=True)
  export_nerfstudio(tmp_path, views)

  def per_frame(meta):  # OPENCV with zero distortion, intrinsics moved into the frames
    meta.update(camera_model="OPENCV", k1=0.0, k2=0.0, p1=0.0, p2=0.0)
    for frame in meta["frames"]:
      frame.update({k: meta[k] for k in ("fl_x", "fl_y", "cx", "cy")})
    for k in ("fl_x", "fl_y", "cx", "cy"):
      meta.pop(k)

  _edit(tmp_path, per_frame)
  _assert_same_cameras(load_nerfstudio(tmp_path)[0].cameras, views.cameras)
  (tmp_path / "images" / "00001_frame_1.png").unlink()
  with pytest.raises(FileNotFoundError, match="00001_frame_1"):
    load_nerfstudio(tmp_path)
  with pytest.raises(FileNotFoundError, match="nerfstudio capture not found"):
    load_nerfstudio(tmp_path / "missing")


def test_training_data_and_planning_pool_of_a_capture(tmp_path):
  """data.kind = "nerfstudio": the holdout split, the points for init_from = "points", and a
  fixed planning pool."""
  from configs import camera_planning
  from mfsample.config_blocks import data_spec
  from mfsample.data import datasets as data_lib
  from mfsample.planning.config import validate as validate_planning
  from mfsample.planning.pool import make_pool
  from mfsample.train.config import validate

  export_nerfstudio(tmp_path, _views(), _points(), applied_transform=NS_PROCESS_DATA_TRANSFORM)
  config = tiny_config()
  config.data.kind = "nerfstudio"
  config.data.path = str(tmp_path)
  config.data.holdout_every = 2
  config.model.init_from = "points"
  validate(config)
  ds = data_lib.load_dataset(data_spec(config.data))
  assert [n[:5] for n in ds.test.names] == ["00000", "00002"] and len(ds.train) == 2
  assert len(ds.points) == 20
  np.testing.assert_allclose(ds.bounds[0], np.percentile(ds.points.xyz, 1, axis=0), rtol=1e-6)
  planning = camera_planning.get_config("tiny")
  planning.data.kind = "nerfstudio"
  planning.data.path = str(tmp_path)
  planning.data.holdout_every = 2
  planning.data.downscale = 1
  planning.max_views = 2
  planning.eval_views = (2,)
  validate_planning(planning)
  pool = make_pool(data_spec(planning.data))
  assert len(pool.candidates) == 2 and len(pool.test) == 2 and len(pool.points) == 20


# ------------------------------------------------------------ a capture read in full or refused


def _capture(tmp_path, **views_kw):
  """An exported capture of 4 frames sharing top-level PINHOLE intrinsics (32 x 24 images)."""
  export_nerfstudio(tmp_path, _views(same_intrinsics=True, **views_kw))
  return tmp_path


def _write_png(path, value, size=(24, 32)):
  path.parent.mkdir(parents=True, exist_ok=True)
  iio.imwrite(path, np.full((*size, 3), value, np.uint8))


@pytest.mark.parametrize("change, message", [
    # A frame listed twice, or the same file spelled twice: both frames named.
    (lambda m: m["frames"].append(dict(m["frames"][1])),
     r"frames\[1\] \('images/00001_frame_1.png'\) and frames\[4\] \('images/00001_frame_1.png'\)"
     r" have the image .*00001_frame_1.png; every frame must be a distinct view"),
    (lambda m: m["frames"].append({**m["frames"][2], "file_path": "./images/00002_frame_2.png"}),
     r"frames\[2\] .* and frames\[4\] \('./images/00002_frame_2.png'\) have the image"),
])
def test_a_frame_listed_twice_is_refused_naming_both(tmp_path, change, message):
  root = _capture(tmp_path)
  _edit(root, change)
  with pytest.raises(DatasetError, match=message):
    load_nerfstudio(root)


def test_frames_are_named_by_their_path_and_names_never_collide(tmp_path):
  """`images/a.png` and `a.png` are two views named apart; `a.png` beside `a.jpg` (one name)
  is refused; frames all under `images/` keep the names without that folder."""
  root = _capture(tmp_path)
  meta = json.loads((root / "transforms.json").read_text())
  first = meta["frames"][0]
  _write_png(root / "images" / "a.png", 10)
  _write_png(root / "a.png", 200)
  _edit(root, lambda m: m.update(frames=[{**first, "file_path": "images/a.png"},
                                         {**first, "file_path": "a.png"}]))
  views, _ = load_nerfstudio(root)
  assert views.names == ("a", "images/a")  # ordered by file path
  np.testing.assert_allclose(views.images[:, 0, 0, 0], [200 / 255, 10 / 255])

  iio.imwrite(root / "a.jpg", np.zeros((24, 32, 3), np.uint8))
  _edit(root, lambda m: m.update(frames=[{**first, "file_path": "a.png"},
                                         {**first, "file_path": "a.jpg"}]))
  with pytest.raises(DatasetError, match=r"frames\[1\] \('a.jpg'\) and frames\[0\] \('a.png'\) "
                                         r"have the view name 'a'"):
    load_nerfstudio(root)


@pytest.mark.parametrize("change, message", [
    # Per-frame camera models and distortion follow the top level's rule.
    (lambda m: m["frames"][1].update(camera_model="OPENCV_FISHEYE"),
     r"frame 'images/00001_frame_1.png' has the camera model 'OPENCV_FISHEYE', which the "
     r"pinhole renderer cannot reproduce; .*--camera-type pinhole"),
    (lambda m: (m.pop("camera_model"), m["frames"][3].update(camera_model="EQUIRECTANGULAR")),
     r"frame 'images/00003_frame_3.png' has the camera model 'EQUIRECTANGULAR'"),
    (lambda m: m["frames"][0].update(camera_model="OPENCV"),
     r"frame 'images/00000_frame_0.png' has camera_model = 'OPENCV' but the top level says "
     r"'PINHOLE'"),
    (lambda m: m.update(camera_model=3), r"'camera_model' must be a string, got 3"),
    (lambda m: m["frames"][2].update(distortion_params=[0.0, 0.1, 0, 0, 0, 0]),
     r"frame 'images/00002_frame_2.png' has the camera model 'PINHOLE' with distortion "
     r"\{'distortion_params': \[0.0, 0.1"),
    (lambda m: (m.update(distortion_params=[0.0] * 6),
                m["frames"][1].update(distortion_params=[0, 0, 0, 0, 0.01, 0])),
     r"frame 'images/00001_frame_1.png' has the camera model .* \{'distortion_params': "),
    (lambda m: m.update(distortion_params=[0.0, 0.0, 0.0, 0.0, -0.002, 0.0]),
     r"frame 'images/00000_frame_0.png' has .* \{'distortion_params \(top level\)'"),
    (lambda m: m["frames"][0].update(k5=0.3), r"distortion \{'k5': 0.3\}"),
    (lambda m: m.update(distortion_params="abc"),
     r"frame 'images/00000_frame_0.png' \(top level\): 'distortion_params' must be a list of "
     r"finite numbers, got 'abc'"),
    (lambda m: m["frames"][2].update(distortion_params=[0, "0"]),
     r"frame 'images/00002_frame_2.png': 'distortion_params' must be a list of finite numbers"),
    (lambda m: m["frames"][2].update(distortion_params=0.0),
     r"'distortion_params' must be a list of finite numbers, got 0.0"),
    (lambda m: m.update(k1="abc"), r"'k1' must be a finite number, got 'abc'"),
    # Masks: the loss has none, so mask_path is refused (a missing mask file alike, named).
    (lambda m: m["frames"][1].update(mask_path="masks/00001.png"),
     r"frame 'images/00001_frame_1.png': 'mask_path' = 'masks/00001.png': masks are not "
     r"supported"),
    (lambda m: m.update(mask_path="masks/all.png"), r"\(top level\): 'mask_path' = "
     r"'masks/all.png': masks are not supported"),
    # Intrinsics no photograph has, named with the frame and the key.
    (lambda m: m.update(cx=-100.0), r"frame 'images/00000_frame_0.png': 'cx' = -100 lies "
     r"outside the image \(0 .. 32 pixels\)"),
    (lambda m: m.update(cy=24.5), r"'cy' = 24.5 lies outside the image \(0 .. 24 pixels\)"),
    (lambda m: m.update(fl_x=1e6), r"'fl_x' gives a focal length of 1e\+06 pixels, over 1000 x "
     r"the image width"),
    (lambda m: m.update(fl_y=0.0), r"focal lengths must be > 0, got fl_x=.*, fl_y=0.0"),
    (lambda m: m.update(fl_x=-20.0), r"focal lengths must be > 0"),
    (lambda m: m.update(fl_x=0.9, fl_y=1.2, cx=0.5, cy=0.5),  # normalised by the image size
     r"'fl_x' gives a focal length of 0.9 pixels, under 0.05 x the image width .* normalised"),
    (lambda m: m.update(w=0), r"the image size w=0, h=24 must be at least 1 pixel"),
    (lambda m: m.update(ply_file_path=3), r"'ply_file_path' must be a non-empty string, got 3"),
    (lambda m: m["frames"][0].update(file_path=""), r"frames\[0\] needs a non-empty 'file_path'"),
])
def test_every_frame_field_is_read_or_refused(tmp_path, change, message):
  root = _capture(tmp_path)
  _edit(root, change)
  with pytest.raises(DatasetError, match=message):
    load_nerfstudio(root)


@pytest.mark.parametrize("change", [
    lambda m: m.update(camera_model="OPENCV", distortion_params=[0.0] * 6),
    lambda m: (m.pop("camera_model"), [f.update(camera_model="PINHOLE") for f in m["frames"]]),
    lambda m: m["frames"][0].update(distortion_params=[], k3=0.0, camera_model="PINHOLE"),
    lambda m: m.update(cx=0.0, cy=24.0),  # the principal point on the image's border
])
def test_pinhole_fields_in_any_place_are_read(tmp_path, change):
  views = _views(same_intrinsics=True)
  export_nerfstudio(tmp_path, views)
  meta = json.loads((tmp_path / "transforms.json").read_text())
  _edit(tmp_path, change)
  back, _ = load_nerfstudio(tmp_path)
  cx = json.loads((tmp_path / "transforms.json").read_text())["cx"]
  np.testing.assert_array_equal(back.cameras.cx, np.float32(cx))
  np.testing.assert_array_equal(back.cameras.fx, np.float32(meta["fl_x"]))


def test_sub_folders_are_kept_in_images_n(tmp_path):
  """`images/cam0/0001.png` reads `images_2/cam0/0001.png` at factor 2 (not
  `images_2/0001.png`); without that copy the frame is refused, naming the file looked for."""
  root = _capture(tmp_path)
  meta = json.loads((root / "transforms.json").read_text())
  frame = meta["frames"][0]
  frames = []
  for cam, value in (("cam0", 30), ("cam1", 90)):
    _write_png(root / "images" / cam / "0001.png", value)
    _write_png(root / "images_2" / cam / "0001.png", value + 1, size=(12, 16))
    frames.append({**frame, "file_path": f"images/{cam}/0001.png"})
  _edit(root, lambda m: m.update(frames=frames))
  full, _ = load_nerfstudio(root)
  half, _ = load_nerfstudio(root, factor=2)
  assert full.names == half.names == ("cam0/0001", "cam1/0001")
  np.testing.assert_allclose(half.images[:, 0, 0, 0] * 255, [31, 91], atol=1e-4)
  np.testing.assert_allclose(half.cameras.fx, full.cameras.fx / 2)

  (root / "images_2" / "cam1" / "0001.png").rename(root / "images_2" / "0001.png")
  with pytest.raises(FileNotFoundError, match=r"images_2/cam1/0001.png"):
    load_nerfstudio(root, factor=2)
  # Frames outside images/ read images_N/<file name> (nerfstudio's rule): two frames of one
  # file name would read one copy, and are refused.
  for cam in ("cam0", "cam1"):
    _write_png(root / cam / "0001.png", 5)
  _edit(root, lambda m: m.update(frames=[{**frame, "file_path": f"{cam}/0001.png"}
                                         for cam in ("cam0", "cam1")]))
  assert load_nerfstudio(root)[0].names == ("cam0/0001", "cam1/0001")
  with pytest.raises(DatasetError, match=r"frames\[0\] \('cam0/0001.png'\) and frames\[1\] "
                                         r"\('cam1/0001.png'\) have the image .*images_2/0001"):
    load_nerfstudio(root, factor=2)


@pytest.mark.parametrize("pixels, message", [
    (np.full((24, 32), np.nan, np.float32), r"x.tif: 768 pixel values are NaN or infinite"),
    (np.where(np.eye(24, 32) > 0, np.inf, 0.5).astype(np.float32), r"24 pixel values are NaN"),
    (np.full((24, 32), 128.0, np.float32), r"x.tif: float pixel values span 128 .. 128; a float "
                                           r"image must hold values in \[0, 1\]"),
    (np.full((24, 32), -0.25, np.float32), r"span -0.25 .. -0.25"),
])
def test_float_images_out_of_range_are_refused_naming_the_file(tmp_path, pixels, message):
  from PIL import Image

  root = _capture(tmp_path)
  Image.fromarray(np.full((24, 32), 0.25, np.float32), mode="F").save(root / "x.tif")
  _edit(root, lambda m: m["frames"][0].update(file_path="x.tif"))
  views, _ = load_nerfstudio(root)  # a float TIFF in [0, 1] is read as stored
  np.testing.assert_array_equal(views.images[views.names.index("x")], 0.25)
  Image.fromarray(pixels, mode="F").save(root / "x.tif")
  with pytest.raises(DatasetError, match=message):
    load_nerfstudio(root)
