"""Tests of mfsample.data: NeRF Synthetic and LLFF loaders, export, errors."""

import json
import math
import os
import shutil
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from mfsample.camera import Camera
from mfsample.data import (
  DatasetError,
  Views,
  export_blender,
  load_blender,
  load_llff,
  poses_bounds_from_cameras,
)

# NeRF Synthetic lego (400 x 400 copies): $MFSAMPLE_LEGO, else a data folder beside the checkout.
LEGO = Path(os.environ.get("MFSAMPLE_LEGO")
            or Path(__file__).parents[2] / ".." / "shared" / "data" / "lego").resolve()
needs_lego = pytest.mark.skipif(not (LEGO / "transforms_train.json").is_file(),
                                reason=f"lego dataset not found at {LEGO}")


def _cameras(num=4, width=24, height=16):
  """A few cameras on a ring around the origin, up = +z."""
  angle = np.linspace(0.0, 2.0 * np.pi, num, endpoint=False)
  eye = np.stack([3.0 * np.cos(angle), 3.0 * np.sin(angle), np.full(num, 1.5)], -1)
  return Camera.look_at(eye.astype(np.float32), np.zeros((num, 3), np.float32),
                        np.array([0.0, 0.0, 1.0], np.float32), 0.8, width, height)


def _views(num=4, width=24, height=16, seed=0, depth=True, alpha=True):
  rng = np.random.default_rng(seed)
  alphas = rng.uniform(0.0, 1.0, (num, height, width)).astype(np.float32)
  alphas[:, :3] = 0.0  # some empty background
  alphas[:, -3:] = 1.0
  colors = rng.uniform(0.0, 1.0, (num, height, width, 3)).astype(np.float32)
  bg = np.ones(3, np.float32)
  images = colors * alphas[..., None] + (1.0 - alphas[..., None]) * bg if alpha else colors
  depths = (rng.uniform(1.0, 5.0, (num, height, width)) * (alphas > 0)).astype(np.float32)
  return Views(images=images.astype(np.float32), cameras=_cameras(num, width, height),
               alphas=alphas if alpha else None, depths=depths if depth else None,
               names=tuple(f"view{i}" for i in range(num)))


def _assert_cameras_close(a, b, atol=1e-5):
  np.testing.assert_allclose(np.asarray(a.world_to_camera), np.asarray(b.world_to_camera),
                             atol=atol)
  for k in ("fx", "fy", "cx", "cy"):
    np.testing.assert_allclose(np.asarray(getattr(a, k)), np.asarray(getattr(b, k)),
                               rtol=1e-6)
  assert (a.width, a.height) == (b.width, b.height)


def test_export_load_round_trip(tmp_path):
  views = _views()
  export_blender(tmp_path, views, split="train")
  loaded = load_blender(tmp_path, "train")
  assert loaded.images.dtype == np.float32 and loaded.images.shape == views.images.shape
  # 8-bit quantisation of colour and alpha: within 1/255 after re-compositing.
  np.testing.assert_allclose(loaded.images, views.images, atol=1.0 / 255 + 1e-6)
  np.testing.assert_allclose(loaded.alphas, views.alphas, atol=0.5 / 255 + 1e-6)
  np.testing.assert_array_equal(loaded.depths, views.depths)  # float32 .npy: exact
  assert loaded.names == views.names
  assert loaded.depth_codes is None
  _assert_cameras_close(loaded.cameras, views.cameras)
  # Once quantised, a second round trip is the identity.
  export_blender(tmp_path / "again", loaded, split="train")
  again = load_blender(tmp_path / "again", "train")
  np.testing.assert_array_equal(again.images, loaded.images)
  np.testing.assert_array_equal(again.alphas, loaded.alphas)
  np.testing.assert_array_equal(again.depths, loaded.depths)
  _assert_cameras_close(again.cameras, loaded.cameras, atol=1e-6)


def test_export_refuses_to_overwrite(tmp_path):
  views = _views(num=1)
  export_blender(tmp_path, views, split="test")
  with pytest.raises(FileExistsError, match="transforms_test.json"):
    export_blender(tmp_path, views, split="test")
  export_blender(tmp_path, views, split="test", overwrite=True)


def test_off_centre_intrinsics_round_trip(tmp_path):
  cams = _cameras(2)
  cams = Camera.create(cams.world_to_camera, 30.0, 30.0, 11.0, 9.5, cams.width, cams.height)
  views = _views(num=2).replace(cameras=cams)
  export_blender(tmp_path, views)
  _assert_cameras_close(load_blender(tmp_path, "train").cameras, cams)


def test_cameras_match_camera_from_blender(tmp_path):
  """The loader's float64 conversion agrees with `Camera.from_blender`."""
  rng = np.random.default_rng(1)
  frames = []
  c2ws = []
  for i in range(3):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                    [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                    [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    c2w = np.eye(4)
    c2w[:3, :3] = rot
    c2w[:3, 3] = rng.normal(size=3)
    c2ws.append(c2w)
    frames.append({"file_path": f"./train/r_{i}", "transform_matrix": c2w.tolist()})
  _write_dataset(tmp_path, frames, camera_angle_x=0.7, size=(8, 12))
  loaded = load_blender(tmp_path, "train")
  ref = Camera.from_blender(np.stack(c2ws), 0.7, 12, 8)
  _assert_cameras_close(loaded.cameras, ref)


def test_downscale_premultiplies_before_compositing(tmp_path):
  rgba = np.zeros((4, 4, 4), np.uint8)
  rgba[0, 0] = [255, 0, 0, 255]  # one opaque red pixel in the top-left 2x2 block
  frames = [{"file_path": "./train/r_0", "transform_matrix": np.eye(4).tolist()}]
  _write_dataset(tmp_path, frames, camera_angle_x=1.0, images=[rgba])
  for bg in ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)):
    views = load_blender(tmp_path, "train", downscale=2, background=bg)
    assert views.images.shape == (1, 2, 2, 3)
    np.testing.assert_allclose(views.alphas[0, 0, 0], 0.25)
    expected = 0.25 * np.array([1.0, 0.0, 0.0]) + 0.75 * np.asarray(bg)
    np.testing.assert_allclose(views.images[0, 0, 0], expected, atol=1e-6)
    np.testing.assert_allclose(views.images[0, 1, 1], bg)
  full = load_blender(tmp_path, "train")
  half = load_blender(tmp_path, "train", downscale=2)
  np.testing.assert_allclose(half.cameras.fx, full.cameras.fx / 2)
  np.testing.assert_allclose(half.cameras.cx, full.cameras.cx / 2)


def test_rgb_images_have_no_alpha(tmp_path):
  views = _views(num=2, alpha=False, depth=False)
  export_blender(tmp_path, views)
  loaded = load_blender(tmp_path, "train", background=(0.0, 0.0, 0.0))
  assert loaded.alphas is None and loaded.depths is None
  np.testing.assert_allclose(loaded.images, views.images, atol=0.5 / 255 + 1e-6)


def test_views_subset_keeps_every_field(tmp_path):
  views = _views(num=4)
  sub = views.subset([2, 0])
  assert len(sub) == 2 and sub.names == ("view2", "view0")
  np.testing.assert_array_equal(sub.depths[0], views.depths[2])
  np.testing.assert_array_equal(np.asarray(sub.cameras.world_to_camera[1]),
                                np.asarray(views.cameras.world_to_camera[0]))


# ------------------------------------------------------------------ Blender errors


def _write_dataset(root, frames, *, camera_angle_x=0.8, size=(4, 4), images=None,
                   split="train"):
  """Writes transforms_{split}.json and an RGBA PNG per frame (unless it already exists)."""
  root = Path(root)
  (root / split).mkdir(parents=True, exist_ok=True)
  for i, frame in enumerate(frames):
    png = root / (frame["file_path"] + ".png")
    png.parent.mkdir(parents=True, exist_ok=True)
    if not png.exists():
      img = images[i] if images is not None else np.full(size + (4,), 128, np.uint8)
      iio.imwrite(png, img)
  meta = {"frames": frames}
  if camera_angle_x is not None:
    meta["camera_angle_x"] = camera_angle_x
  (root / f"transforms_{split}.json").write_text(json.dumps(meta))


def _frame(i, matrix=None):
  return {"file_path": f"./train/r_{i}",
          "transform_matrix": (np.eye(4) if matrix is None else matrix).tolist()}


def test_error_missing_folder(tmp_path):
  with pytest.raises(FileNotFoundError, match="nowhere"):
    load_blender(tmp_path / "nowhere", "train")


def test_error_no_transforms(tmp_path):
  with pytest.raises(FileNotFoundError, match="transforms_train.json"):
    load_blender(tmp_path, "train")


def test_error_unknown_split(tmp_path):
  _write_dataset(tmp_path, [_frame(0)])
  with pytest.raises(DatasetError, match=r"unknown split 'trian'.*available splits.*train"):
    load_blender(tmp_path, "trian")
  with pytest.raises(ValueError, match="split"):
    load_blender(tmp_path, "")


def test_error_malformed_json(tmp_path):
  _write_dataset(tmp_path, [_frame(0)])
  (tmp_path / "transforms_train.json").write_text('{"frames": [')
  with pytest.raises(DatasetError, match=r"transforms_train.json: malformed json"):
    load_blender(tmp_path, "train")


@pytest.mark.parametrize("meta, message", [
    ({"camera_angle_x": 0.8}, "'frames'"),
    ({"camera_angle_x": 0.8, "frames": []}, "'frames'"),
    ({"camera_angle_x": 0.8, "frames": [{"transform_matrix": np.eye(4).tolist()}]},
     "frame 0: missing key 'file_path'"),
    ({"camera_angle_x": 0.8, "frames": [{"file_path": "./train/r_0"}]},
     "frame 0: missing key 'transform_matrix'"),
    ({"frames": [{"file_path": "./train/r_0", "transform_matrix": np.eye(4).tolist()}]},
     "camera_angle_x"),
])
def test_error_missing_keys(tmp_path, meta, message):
  _write_dataset(tmp_path, [_frame(0)])
  (tmp_path / "transforms_train.json").write_text(json.dumps(meta))
  with pytest.raises(DatasetError, match=message):
    load_blender(tmp_path, "train")


def test_error_missing_image(tmp_path):
  _write_dataset(tmp_path, [_frame(0), _frame(1)])
  (tmp_path / "train" / "r_1.png").unlink()
  with pytest.raises(FileNotFoundError, match=r"r_1\.png"):
    load_blender(tmp_path, "train")


def test_error_images_of_different_sizes(tmp_path):
  images = [np.zeros((4, 4, 4), np.uint8), np.zeros((4, 6, 4), np.uint8)]
  _write_dataset(tmp_path, [_frame(0), _frame(1)], images=images)
  with pytest.raises(DatasetError, match=r"r_1\.png: image is 6x4 but the first frame"):
    load_blender(tmp_path, "train")


@pytest.mark.parametrize("matrix, message", [
    (np.full((4, 4), np.nan), "non-finite"),
    (np.diag([2.0, 2.0, 2.0, 1.0]), "not rigid"),
    (np.diag([1.0, 1.0, -1.0, 1.0]), "not rigid"),  # a mirror, det -1
    (np.eye(3), "3x4 or 4x4"),
])
def test_error_bad_pose(tmp_path, matrix, message):
  _write_dataset(tmp_path, [_frame(0), _frame(1, matrix)])
  with pytest.raises(DatasetError, match=rf"transforms_train.json frame 1: .*{message}"):
    load_blender(tmp_path, "train")


def test_error_bad_downscale(tmp_path):
  _write_dataset(tmp_path, [_frame(0)], size=(4, 6))
  with pytest.raises(DatasetError, match=r"r_0\.png: image size 6x4 is not divisible"):
    load_blender(tmp_path, "train", downscale=4)
  with pytest.raises(ValueError, match="downscale"):
    load_blender(tmp_path, "train", downscale=0)


def test_error_partial_depth(tmp_path):
  views = _views(num=2)
  export_blender(tmp_path, views)
  meta = json.loads((tmp_path / "transforms_train.json").read_text())
  del meta["frames"][1]["depth_file_path"]
  (tmp_path / "transforms_train.json").write_text(json.dumps(meta))
  with pytest.raises(DatasetError, match="frame 1 has no depth"):
    load_blender(tmp_path, "train")


# ------------------------------------------------------------------ real lego


@pytest.fixture(scope="module")
def lego_train():
  return load_blender(LEGO, "train", downscale=4)


@needs_lego
def test_lego_every_train_camera_sees_the_object(lego_train):
  views = lego_train
  assert views.images.shape == (100, 100, 100, 3) and views.alphas.shape == (100, 100, 100)
  assert views.depths is None and views.depth_codes is None  # train has no depth
  uv, z = views.cameras.project(np.zeros((1, 3), np.float32))
  uv, z = np.asarray(uv)[:, 0], np.asarray(z)[:, 0]
  assert np.all(z > 0)
  assert np.all((uv > 0) & (uv < 100))
  a = views.alphas
  ii, jj = np.mgrid[:100, :100] + 0.5
  centroid = np.stack([(a * jj).sum((1, 2)), (a * ii).sum((1, 2))], -1) / a.sum((1, 2))[:, None]
  assert np.max(np.linalg.norm(centroid - uv, axis=-1)) < 15.0  # pixels, of 100


@needs_lego
def test_lego_visual_hull_is_consistent(lego_train):
  """Carve a voxel grid with all 100 masks; the hull must re-cover every mask. A flipped
  axis convention (e.g. image rotated by 180 degrees) fails this (~47% coverage)."""
  views = lego_train
  g = np.linspace(-1.5, 1.5, 40)
  points = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3).astype(np.float32)
  uv, z = views.cameras.project(points)
  uv, z = np.asarray(uv), np.asarray(z)
  j, i = np.floor(uv[..., 0]).astype(int), np.floor(uv[..., 1]).astype(int)
  inside = (z > 0) & (i >= 0) & (i < 100) & (j >= 0) & (j < 100)
  v_idx = np.arange(len(views))[:, None]
  alpha = np.where(inside, views.alphas[v_idx, np.clip(i, 0, 99), np.clip(j, 0, 99)], 0.0)
  hull = np.all(alpha > 0.5, axis=0)
  assert hull.sum() > 1000
  for k in range(len(views)):
    covered = np.zeros((100, 100), bool)
    for di in (-1, 0, 1):
      for dj in (-1, 0, 1):
        covered[np.clip(i[k, hull] + di, 0, 99), np.clip(j[k, hull] + dj, 0, 99)] = True
    mask = views.alphas[k] > 0.5
    assert (covered & mask).sum() / mask.sum() > 0.8, f"view {k}"


@pytest.fixture
def lego_subset(tmp_path):
  """The first 5 test frames of lego (with their depth PNGs), linked into a tmp folder."""
  meta = json.loads((LEGO / "transforms_test.json").read_text())
  meta["frames"] = meta["frames"][:5]
  (tmp_path / "test").mkdir()
  for frame in meta["frames"]:
    stem = Path(frame["file_path"]).name
    for name in (f"{stem}.png", f"{stem}_depth_0001.png"):
      (tmp_path / "test" / name).symlink_to(LEGO / "test" / name)
  (tmp_path / "transforms_test.json").write_text(json.dumps(meta))
  return tmp_path


@needs_lego
def test_lego_downscale_keeps_cameras_consistent(lego_subset):
  full = load_blender(lego_subset, "test")
  small = load_blender(lego_subset, "test", downscale=4)
  assert full.images.shape[1:3] == (400, 400) and small.images.shape[1:3] == (100, 100)
  np.testing.assert_array_equal(np.asarray(small.cameras.world_to_camera),
                                np.asarray(full.cameras.world_to_camera))
  np.testing.assert_allclose(np.asarray(small.cameras.fx), np.asarray(full.cameras.fx) / 4,
                             rtol=1e-6)
  # Any 3D point lands at a quarter of its full-resolution pixel coordinates.
  points = np.random.default_rng(0).uniform(-1, 1, (50, 3)).astype(np.float32)
  uv_full, _ = full.cameras.project(points)
  uv_small, _ = small.cameras.project(points)
  np.testing.assert_allclose(np.asarray(uv_small), np.asarray(uv_full) / 4, atol=1e-3)
  # Images and masks are 4x4 box filters of the full-resolution ones.
  box = lambda x: x.reshape(x.shape[0], 100, 4, 100, 4, *x.shape[3:]).mean(axis=(2, 4))
  np.testing.assert_allclose(small.alphas, box(full.alphas), atol=1e-5)
  np.testing.assert_allclose(small.images, box(full.images), atol=1e-5)  # white bg: linear


@needs_lego
def test_lego_depth_is_exposed_as_non_metric_codes(lego_subset):
  views = load_blender(lego_subset, "test", downscale=4)
  assert views.depths is None, "lego's 8-bit depth is not metric and must not be in depths"
  codes = views.depth_codes
  assert codes.shape == (5, 100, 100) and codes.dtype == np.float32
  assert np.all(codes[views.alphas == 0] == 0) and codes.max() <= 1.0
  assert np.all(codes[views.alphas > 0.99] > 0)


# ------------------------------------------------------------------ LLFF


def _write_llff(root, cameras, bounds, *, factor=8, full_size=None):
  """Writes poses_bounds.npy (at full_size = factor x the camera size) and images_{factor}."""
  root = Path(root)
  root.mkdir(parents=True, exist_ok=True)
  pb = poses_bounds_from_cameras(cameras, bounds)
  if factor != 1:  # the stored hwf is at full resolution
    pb[:, 4], pb[:, 9], pb[:, 14] = (cameras.height * factor, cameras.width * factor,
                                     np.asarray(cameras.fx) * factor)
  np.save(root / "poses_bounds.npy", pb)
  folder = root / ("images" if factor == 1 else f"images_{factor}")
  folder.mkdir(exist_ok=True)
  rng = np.random.default_rng(0)
  for v in range(len(cameras)):
    img = rng.integers(0, 256, (cameras.height, cameras.width, 3), dtype=np.uint8)
    iio.imwrite(folder / f"IMG_{v:04d}.png", img)
  return folder


def test_llff_round_trip(tmp_path):
  cams = _cameras(5, width=20, height=14)
  bounds = np.stack([np.linspace(1.0, 2.0, 5), np.linspace(6.0, 8.0, 5)], -1)
  folder = _write_llff(tmp_path, cams, bounds)
  views, loaded_bounds = load_llff(tmp_path, factor=8)
  assert views.images.shape == (5, 14, 20, 3) and views.alphas is None
  assert views.names == tuple(f"IMG_{v:04d}" for v in range(5))
  np.testing.assert_allclose(loaded_bounds, bounds, rtol=1e-6)
  _assert_cameras_close(views.cameras, cams)
  first = iio.imread(folder / "IMG_0000.png").astype(np.float32) / 255
  np.testing.assert_allclose(views.images[0], first)


def test_llff_axis_convention():
  """An LLFF pose written by hand: camera at the origin, down = -y, right = +x, back = +z
  (looking down -z). A point in front, up and to the right lands up-right of centre."""
  import tempfile
  with tempfile.TemporaryDirectory() as tmp:
    mat = np.array([[0.0, 1.0, 0.0, 0.0, 80.0],
                    [-1.0, 0.0, 0.0, 0.0, 160.0],
                    [0.0, 0.0, 1.0, 0.0, 100.0]])
    row = np.concatenate([mat.ravel(), [1.0, 10.0]])[None]
    np.save(Path(tmp) / "poses_bounds.npy", row)
    (Path(tmp) / "images_8").mkdir()
    iio.imwrite(Path(tmp) / "images_8" / "a.png", np.zeros((10, 20, 3), np.uint8))
    views, _ = load_llff(tmp)
  cam = views.cameras[0]
  assert float(cam.fx) == pytest.approx(100.0 / 8)
  uv, z = cam.project(np.array([[0.4, 0.2, -2.0]], np.float32))
  u, v = np.asarray(uv)[0]
  assert float(z[0]) == pytest.approx(2.0)
  assert u == pytest.approx(10.0 + 12.5 * 0.4 / 2.0)
  assert v == pytest.approx(5.0 - 12.5 * 0.2 / 2.0)


def test_llff_factor_one_uses_images_folder(tmp_path):
  cams = _cameras(2, width=8, height=6)
  _write_llff(tmp_path, cams, np.array([[1.0, 5.0], [1.0, 5.0]]), factor=1)
  views, _ = load_llff(tmp_path, factor=1)
  _assert_cameras_close(views.cameras, cams)


@pytest.mark.parametrize("breakage, error, message", [
    ("no_poses", FileNotFoundError, "poses_bounds.npy"),
    ("bad_shape", DatasetError, r"poses_bounds.npy: expected an array of shape \[V, 17\]"),
    ("no_images", FileNotFoundError, "images_8"),
    ("count", DatasetError, "images_8: 2 images but .* has 3 poses"),
    ("sizes", DatasetError, r"IMG_0001\.png: image is 9x7 but IMG_0000\.png is 8x6"),
    ("nan", DatasetError, "row 1 has non-finite entries"),
    ("scaled", DatasetError, "row 2: pose is not rigid"),
    ("bounds", DatasetError, "row 0 has invalid bounds"),
])
def test_llff_errors(tmp_path, breakage, error, message):
  cams = _cameras(3, width=8, height=6)
  folder = _write_llff(tmp_path, cams, np.tile([[1.0, 5.0]], (3, 1)))
  pb = np.load(tmp_path / "poses_bounds.npy")
  if breakage == "no_poses":
    (tmp_path / "poses_bounds.npy").unlink()
  elif breakage == "bad_shape":
    np.save(tmp_path / "poses_bounds.npy", pb[:, :15])
  elif breakage == "no_images":
    shutil.rmtree(folder)
  elif breakage == "count":
    (folder / "IMG_0002.png").unlink()
  elif breakage == "sizes":
    iio.imwrite(folder / "IMG_0001.png", np.zeros((7, 9, 3), np.uint8))
  elif breakage == "nan":
    pb[1, 3] = np.nan
    np.save(tmp_path / "poses_bounds.npy", pb)
  elif breakage == "scaled":
    pb[2, :15] = (pb[2, :15].reshape(3, 5) * [2, 2, 2, 1, 1]).ravel()
    np.save(tmp_path / "poses_bounds.npy", pb)
  elif breakage == "bounds":
    pb[0, 15:] = [5.0, 1.0]
    np.save(tmp_path / "poses_bounds.npy", pb)
  with pytest.raises(error, match=message):
    load_llff(tmp_path)


def test_llff_error_missing_folder(tmp_path):
  with pytest.raises(FileNotFoundError, match="LLFF dataset folder"):
    load_llff(tmp_path / "nope")


def test_llff_focal_scales_with_actual_image_size(tmp_path):
  cams = _cameras(2, width=16, height=12)
  _write_llff(tmp_path, cams, np.array([[1.0, 5.0], [1.0, 5.0]]), factor=4)
  views, _ = load_llff(tmp_path, factor=4)
  np.testing.assert_allclose(np.asarray(views.cameras.fx), np.asarray(cams.fx), rtol=1e-6)
  assert math.isclose(float(views.cameras.cx[0]), 8.0)
