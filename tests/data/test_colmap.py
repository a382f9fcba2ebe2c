"""Tests of mfsample.data.colmap: COLMAP captures in, with the points where they belong."""

import shutil

import imageio.v3 as iio
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import tiny_config, tiny_start

from mfsample.camera import Camera
from mfsample.data import DatasetError, PointCloud, Views, export_colmap, load_colmap
from mfsample.data._io import area_downscale
from mfsample.gaussians import Gaussians
from mfsample.planning.poses import downscale_camera
from mfsample.renderer import RenderSettings, render
from mfsample.renderer.sh import rgb_to_sh_dc

pycolmap = pytest.importorskip("pycolmap")

SETTINGS = RenderSettings(max_intersections=1 << 12)
COLOURS = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1], [1, 0, 1]],
                   np.float32)


def _scene():
  """Six small opaque Gaussians on a 3 x 2 grid in the plane z = 0, one colour each, and
  four cameras in front of it with unequal focal lengths and off-centre principal points."""
  xyz = np.array([[x, y, 0.0] for y in (-0.25, 0.25) for x in (-0.4, 0.0, 0.4)], np.float32)
  gaussians = Gaussians(
      means=jnp.asarray(xyz), scales=jnp.full((6, 3), 0.02), quats=jnp.tile(
          jnp.array([1.0, 0, 0, 0]), (6, 1)), opacities=jnp.full((6,), 0.99),
      sh=jnp.asarray(rgb_to_sh_dc(COLOURS))[:, None, :])
  eyes = np.array([[0.0, -0.3, -3.0], [0.5, 0.2, -2.8], [-0.6, 0.1, -3.1], [0.2, 0.4, -2.6]])
  looks = Camera.look_at(jnp.asarray(eyes, jnp.float32), jnp.zeros((4, 3)),
                         jnp.array([0.0, -1.0, 0.0]), 0.6, 64, 48)
  cameras = Camera.create(looks.world_to_camera, looks.fx, looks.fx * 1.05,
                          jnp.array([31.0, 33.5, 32.25, 30.0]), jnp.array([24.0, 22.5, 25.0,
                                                                           23.75]), 64, 48)
  return gaussians, cameras, PointCloud(xyz, COLOURS)


def _render_all(gaussians, cameras):
  return np.stack([np.asarray(jnp.clip(render(gaussians, cameras[i], settings=SETTINGS).rgb,
                                       0.0, 1.0)) for i in range(len(cameras))])


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
  """A COLMAP capture written by `export_colmap` (pycolmap's writer), with a half-size
  `images_2/` copy, and a text-format twin of its model."""
  from mfsample.data import Views

  root = tmp_path_factory.mktemp("capture")
  gaussians, cameras, points = _scene()
  images = _render_all(gaussians, cameras)
  views = Views(images, cameras, names=tuple(f"frame_{i}" for i in range(4)))
  export_colmap(root, views, points)
  # images_2/: a 2x box filter, as downscaled folders are made (pixel p -> p / 2 exactly).
  (root / "images_2").mkdir()
  for name, image in zip(sorted(p.name for p in (root / "images").iterdir()), images,
                         strict=True):
    half = area_downscale(image, 2)
    iio.imwrite(root / "images_2" / name, np.round(half * 255).astype(np.uint8))
  text = tmp_path_factory.mktemp("text")
  shutil.copytree(root / "images", text / "images")
  recon = pycolmap.Reconstruction(str(root / "sparse" / "0"))
  (text / "sparse" / "0").mkdir(parents=True)
  recon.write_text(str(text / "sparse" / "0"))
  return root, text, gaussians, cameras, points, images


@pytest.mark.parametrize("fmt", ["binary", "text"])
def test_round_trip_poses_intrinsics_order_points(capture, fmt):
  root, text, _, cameras, points, images = capture
  views, loaded = load_colmap(root if fmt == "binary" else text)
  assert views.names == tuple(f"{i:05d}_frame_{i}" for i in range(4))  # the order kept
  assert (views.cameras.width, views.cameras.height) == (64, 48)
  np.testing.assert_allclose(views.cameras.world_to_camera, cameras.world_to_camera, atol=1e-6)
  for k in ("fx", "fy", "cx", "cy"):
    np.testing.assert_array_equal(getattr(views.cameras, k), getattr(cameras, k), err_msg=k)
  np.testing.assert_array_equal(loaded.xyz, points.xyz)
  np.testing.assert_allclose(loaded.rgb, points.rgb, atol=0.5 / 255)
  np.testing.assert_allclose(views.images, images, atol=0.5 / 255 + 1e-6)  # 8-bit files
  assert views.alphas is None


def test_projection_agrees_with_colmaps_own(capture):
  """pycolmap's projection of every point (COLMAP's conventions, not this loader's) lands
  where the loaded `Camera` projects it: axes, pose direction and the half-pixel offset."""
  root, *_ = capture
  views, points = load_colmap(root)
  recon = pycolmap.Reconstruction(str(root / "sparse" / "0"))
  for image in recon.images.values():
    pose = image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
    cam_xyz = np.stack([pose * p.astype(np.float64) for p in points.xyz])
    want = recon.cameras[image.camera_id].img_from_cam(cam_xyz)
    got, _ = views.cameras[views.names.index(image.name[:-4])].project(jnp.asarray(points.xyz))
    np.testing.assert_allclose(np.asarray(got), want, atol=2e-4)


def test_known_points_land_where_they_belong(capture):
  """In every image on disk (full size and images_2), the blob of each point is centred on
  the pixel where the loaded camera projects that point, and rendering the points with the
  loaded cameras reproduces the images."""
  root, _, gaussians, *_ = capture
  for factor in (1, 2):
    views, points = load_colmap(root, factor=factor)
    uv, _ = views.cameras.project(jnp.asarray(points.xyz)[None])
    uv = np.asarray(uv)
    for v in range(len(views)):
      for p, colour in enumerate(COLOURS):
        u0, v0 = uv[v, p]
        i0, j0 = int(v0), int(u0)
        rows, cols = np.mgrid[i0 - 3:i0 + 4, j0 - 3:j0 + 4]
        # The point's own colour, less what its neighbours share with it.
        weight = np.min(views.images[v, rows, cols][..., colour > 0], axis=-1)
        weight = weight - np.max(np.append(views.images[v, rows, cols][..., colour == 0],
                                           np.zeros(rows.shape + (1,)), axis=-1), axis=-1)
        weight = np.clip(weight, 0.0, None)
        centre = (np.sum(weight * (cols + 0.5)) / weight.sum(),
                  np.sum(weight * (rows + 0.5)) / weight.sum())
        np.testing.assert_allclose(centre, (u0, v0), atol=0.15 * (3 - factor),
                                   err_msg=f"factor {factor}, view {v}, point {p}")
    assert views.cameras.width == 64 // factor
  views, _ = load_colmap(root)
  np.testing.assert_allclose(_render_all(gaussians, views.cameras), views.images,
                             atol=0.5 / 255 + 2e-4)


def test_images_n_scales_the_intrinsics(capture):
  root, _, _, cameras, *_ = capture
  views, _ = load_colmap(root, factor=2)
  half = downscale_camera(cameras, 2)
  for k in ("fx", "fy", "cx", "cy"):
    np.testing.assert_allclose(getattr(views.cameras, k), getattr(half, k), rtol=1e-6)
  assert views.images.shape == (4, 24, 32, 3)


def _text_model(root, camera_line, image_lines, point_lines=()):
  """A sparse model written by hand in COLMAP's documented text format."""
  sparse = root / "sparse" / "0"
  sparse.mkdir(parents=True, exist_ok=True)
  (sparse / "cameras.txt").write_text("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
                                      + camera_line + "\n")
  (sparse / "images.txt").write_text(
      "# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n# POINTS2D[]\n"
      + "".join(line + "\n\n" for line in image_lines))
  (sparse / "points3D.txt").write_text("".join(line + "\n" for line in point_lines))
  (root / "images").mkdir(exist_ok=True)
  for line in image_lines:
    iio.imwrite(root / "images" / line.split()[-1], np.zeros((30, 40, 3), np.uint8))
  return root


def test_hand_written_text_model_follows_colmaps_conventions(tmp_path):
  """A camera rotated 90 degrees about its z axis (quaternion w, x, y, z) and moved 2 along
  it; a point in front lands where COLMAP's pinhole formula puts it (centre of the top-left
  pixel at 0.5, 0.5)."""
  c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
  _text_model(tmp_path, "7 PINHOLE 40 30 50 60 20.5 14.5",
              [f"3 {c} 0 0 {s} 0.1 0 2 7 b.png", "1 1 0 0 0 0 0 1 7 a.png"],
              ["4 0.1 -0.2 0.3 255 128 0 0.5"])
  views, points = load_colmap(tmp_path)
  assert views.names == ("a", "b")  # by name, not by image id
  np.testing.assert_allclose(views.cameras.world_to_camera[1], [[0, -1, 0, 0.1], [1, 0, 0, 0],
                                                                [0, 0, 1, 2], [0, 0, 0, 1]],
                             atol=1e-7)
  np.testing.assert_allclose(points.rgb, [[1.0, 128 / 255, 0.0]])
  uv, z = views.cameras[1].project(jnp.asarray(points.xyz))
  x, y, depth = 0.2 + 0.1, 0.1, 2.3  # R p + t
  np.testing.assert_allclose(np.asarray(uv)[0], [50 * x / depth + 20.5, 60 * y / depth + 14.5],
                             rtol=1e-6)
  assert float(z[0]) == pytest.approx(depth)


@pytest.mark.parametrize("camera_line, loads", [
    ("1 SIMPLE_PINHOLE 40 30 50 20 15", True),
    ("1 SIMPLE_RADIAL 40 30 50 20 15 0", True),  # zero distortion: a pinhole
    ("1 OPENCV 40 30 50 51 20 15 0 0 0 0", True),
    ("1 SIMPLE_RADIAL 40 30 50 20 15 0.01", False),
    ("1 OPENCV 40 30 50 51 20 15 -0.1 0.01 0 0", False),
    ("1 OPENCV_FISHEYE 40 30 50 51 20 15 0 0 0 0", False),
])
def test_distorted_cameras_are_refused_by_name(tmp_path, camera_line, loads):
  _text_model(tmp_path, camera_line, ["1 1 0 0 0 0 0 1 1 a.png"])
  if loads:
    views, points = load_colmap(tmp_path)
    assert float(views.cameras.fx[0]) == 50.0 and len(points) == 0
  else:
    model = camera_line.split()[1]
    with pytest.raises(DatasetError, match=f"camera 1 .*'a.png'.* {model}.*image_undistorter"):
      load_colmap(tmp_path)


def test_errors_name_what_is_missing(tmp_path, capture):
  with pytest.raises(FileNotFoundError, match="no COLMAP sparse model"):
    load_colmap(tmp_path)
  root, *_ = capture
  with pytest.raises(FileNotFoundError, match=r"images_4 .*images, images_2"):
    load_colmap(root, factor=4, make_downscaled=False)  # (tests/data/test_downscaled.py: made)
  broken = tmp_path / "broken"
  shutil.copytree(root, broken)
  (broken / "images" / "00002_frame_2.png").unlink()
  with pytest.raises(FileNotFoundError, match="00002_frame_2.png"):
    load_colmap(broken)
  iio.imwrite(broken / "images" / "00002_frame_2.jpg", np.zeros((48, 64, 3), np.uint8))
  load_colmap(broken)  # another extension of the same stem is found
  iio.imwrite(broken / "images" / "00001_frame_1.png", np.zeros((40, 64, 3), np.uint8))
  with pytest.raises(DatasetError, match=r"00001_frame_1.png: image is 64x40 but"):
    load_colmap(broken)
  (broken / "sparse" / "0" / "images.bin").write_bytes(b"\x05\x00\x00")
  with pytest.raises(DatasetError, match=r"images.bin: truncated: the number of images"):
    load_colmap(broken)
  with pytest.raises(FileExistsError):
    export_colmap(root, load_colmap(root)[0])


def test_training_data_and_sfm_initialisation(capture):
  """data.kind = "colmap": every 2nd image held out, the points' box, and a model that starts
  at the SfM points with their colours (the 3DGS initialisation)."""
  from mfsample.config_blocks import data_spec
  from mfsample.data import datasets as data_lib

  root, *_ = capture
  config = tiny_config()
  config.data.kind = "colmap"
  config.data.path = str(root)
  config.data.holdout_every = 2
  config.model.init_from = "points"
  ds = data_lib.load_dataset(data_spec(config.data))
  assert [n[:5] for n in ds.test.names] == ["00000", "00002"] and len(ds.train) == 2
  np.testing.assert_allclose(ds.bounds[0], [-0.4, -0.25, 0.0], atol=1e-6)
  _, model = tiny_start(config, ds)
  assert model.num_live == 6
  np.testing.assert_array_equal(np.asarray(model.params.mean["means"])[:6], ds.points.xyz)
  np.testing.assert_allclose(np.asarray(model.params.mean["sh_dc"])[:6],
                             np.asarray(rgb_to_sh_dc(COLOURS)), atol=1e-5)
  with pytest.raises(ValueError, match="init_from = 'points' needs a dataset"):
    tiny_start(config, ds._replace(points=None))


def test_planning_pool_of_a_capture(capture):
  from configs import camera_planning
  from mfsample.config_blocks import data_spec
  from mfsample.planning.pool import make_pool

  root, *_ = capture
  config = camera_planning.get_config("tiny")
  config.data.kind = "colmap"
  config.data.path = str(root)
  config.data.downscale = 1
  config.data.holdout_every = 2
  pool = make_pool(data_spec(config.data))
  assert len(pool.candidates) == 2 and len(pool.test) == 2 and pool.oracle is None
  assert len(pool.points) == 6 and pool.sphere.width == 64


# ---------------------------------------------------------------------- camera parameters

PINHOLE = ("fx", "fy", "cx", "cy")


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
@pytest.mark.parametrize("index", range(4))
def test_a_non_finite_camera_parameter_is_named_in_a_binary_model(tmp_path, index, value):
  """pycolmap's binary reader keeps a NaN parameter: the walk names the camera first."""
  w2c = np.eye(4, dtype=np.float32)
  w2c[2, 3] = 2.0
  views = Views(np.zeros((2, 8, 8, 3), np.float32),
                Camera.create(np.stack([w2c] * 2), 6.0, 6.0, 4.0, 4.0, 8, 8))
  sparse = export_colmap(tmp_path, views)
  data = bytearray((sparse / "cameras.bin").read_bytes())
  data[32 + 8 * index:40 + 8 * index] = np.float64(value).tobytes()  # after id, model, w, h
  (sparse / "cameras.bin").write_bytes(bytes(data))
  with pytest.raises(DatasetError, match=rf"cameras\.bin: camera 1 has non-finite parameters: "
                                         rf"{PINHOLE[index]} = {value}"):
    load_colmap(tmp_path)


@pytest.mark.parametrize("params, message", [
    ("nan 60 20 15", "camera 7 has non-finite parameters: fx = nan"),
    ("50 60 inf 15", "camera 7 has non-finite parameters: cx = inf"),
    ("50 NaN 20 -inf", "camera 7 has non-finite parameters: fy = nan, cy = -inf"),
    ("50 60 20", r"camera 7 \(PINHOLE\) has 3 parameters; the model has 4 \(fx, fy, cx, cy\)"),
])
def test_camera_parameters_of_a_text_model_are_checked_before_pycolmap(tmp_path, params,
                                                                       message):
  """pycolmap's text reader failed with "Check failed: camera.VerifyParams()", no camera id."""
  _text_model(tmp_path, f"7 PINHOLE 40 30 {params}", ["1 1 0 0 0 0 0 1 7 a.png"])
  with pytest.raises(DatasetError, match=rf"cameras\.txt line 2: {message}"):
    load_colmap(tmp_path)

