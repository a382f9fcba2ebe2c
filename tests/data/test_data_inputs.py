"""Hostile inputs to mfsample.data's loaders and exports: images, json, LLFF, COLMAP, .ply, Views.

For each entry point, a table of bad inputs and what they give: each row is a bad input and
its expected outcome, a clear error whose message names the field or the file, or a defined
behaviour (docs/reliability.md lists the same tables).
"""

import json
import struct
import zlib

import numpy as np
import pytest
from hostile_testlib import NAN, W2C
from PIL import Image

from mfsample.camera import Camera
from mfsample.data import (
  DatasetError,
  PointCloud,
  Views,
  export_blender,
  export_colmap,
  load_blender,
  load_colmap,
  load_llff,
  load_ply,
  poses_bounds_from_cameras,
)
from mfsample.data._io import read_image, read_json

# ====================================================================== loaders


def _png(path, array, bit_depth=16):
  """Writes a non-palette PNG of [H, W, C] unsigned integers (any bit depth PNG allows)."""
  h, w, c = array.shape
  colour_type = {1: 0, 2: 4, 3: 2, 4: 6}[c]
  dtype = ">u2" if bit_depth == 16 else ">u1"
  raw = b"".join(b"\x00" + array[i].astype(dtype).tobytes() for i in range(h))

  def chunk(tag, data):
    return (struct.pack(">I", len(data)) + tag + data
            + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF))

  header = struct.pack(">IIBBBBB", w, h, bit_depth, colour_type, 0, 0, 0)
  with open(path, "wb") as f:
    f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw))
            + chunk(b"IEND", b""))


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_16_bit_pngs_are_read_at_full_precision(tmp_path, channels):
  values = np.random.default_rng(channels).integers(0, 65536, (3, 5, channels), np.uint16)
  _png(tmp_path / "x.png", values)
  color, alpha = read_image(tmp_path / "x.png")
  expected = values.astype(np.float32) / 65535.0
  want_color = expected[..., :3] if channels >= 3 else np.repeat(expected[..., :1], 3, -1)
  np.testing.assert_array_equal(color, want_color)  # not rounded to 8 bits
  if channels in (2, 4):
    np.testing.assert_array_equal(alpha, expected[..., -1])
  else:
    assert alpha is None


def _pillow(tmp_path, name, make):
  path = tmp_path / name
  make().save(path)
  return path


@pytest.mark.parametrize("name, make, color, alpha", [
    ("palette.png", lambda: Image.fromarray(np.array([[0, 255]], np.uint8)).convert("P"),
     [[0.0] * 3, [1.0] * 3], None),
    ("bilevel.png", lambda: Image.fromarray(np.array([[False, True]])), [[0.0] * 3, [1.0] * 3],
     None),
    ("cmyk.jpg", lambda: Image.new("CMYK", (2, 1), (0, 0, 0, 0)), [[1.0] * 3] * 2, None),
    ("grey_alpha.png", lambda: Image.fromarray(np.array([[[51, 255], [102, 0]]], np.uint8), "LA"),
     [[0.2] * 3, [0.4] * 3], [1.0, 0.0]),
])
def test_image_modes_are_decoded_not_misread(tmp_path, name, make, color, alpha):
  c, a = read_image(_pillow(tmp_path, name, make))
  np.testing.assert_allclose(c[0], color, atol=2 / 255)  # a CMYK file is RGB, not RGBA
  if alpha is None:
    assert a is None
  else:
    np.testing.assert_allclose(a[0], alpha, atol=1e-6)


@pytest.mark.parametrize("content", [b"", b"not an image", b"\x89PNG\r\n\x1a\n" + b"\x00" * 30])
def test_unreadable_images_name_the_file(tmp_path, content):
  (tmp_path / "broken.png").write_bytes(content)
  with pytest.raises(DatasetError, match=r"broken.png: cannot read image"):
    read_image(tmp_path / "broken.png")


def _blender(tmp_path, meta_changes=None, frame_changes=None):
  """A one-frame NeRF Synthetic folder with `changes` applied to its json."""
  (tmp_path / "train").mkdir(exist_ok=True)
  Image.fromarray(np.zeros((4, 6, 4), np.uint8)).save(tmp_path / "train" / "r_0.png")
  c2w = np.linalg.inv(np.diag([1.0, -1, -1, 1]) @ W2C @ np.diag([1.0, -1, -1, 1]))
  frame = {"file_path": "./train/r_0", "transform_matrix": c2w.tolist(), **(frame_changes or {})}
  meta = {"camera_angle_x": 0.8, "frames": [frame], **(meta_changes or {})}
  (tmp_path / "transforms_train.json").write_text(json.dumps(meta))
  return tmp_path


@pytest.mark.parametrize("meta, frame, message", [
    ({"camera_angle_x": "0.8"}, {}, r"transforms_train.json: 'camera_angle_x' must be a finite "
                                    r"number, got '0.8'"),
    ({"camera_angle_x": True}, {}, "'camera_angle_x' must be a finite number, got True"),
    ({"camera_angle_x": 50.0}, {}, r"'camera_angle_x' = 50.0 is not in \(0, pi\) radians"),
    ({}, {"camera_angle_x": [0.8]}, r"frame 0: 'camera_angle_x' must be a finite number"),
    ({"fl_x": "500"}, {}, "'fl_x' must be a finite number, got '500'"),
    ({"fl_x": -5.0}, {}, "focal lengths must be > 0"),
    ({}, {"cx": None, "cy": NAN}, "frame 0: 'cy' must be a finite number, got nan"),
    ({"w": "6"}, {}, "'w' must be an integer, got '6'"),
    ({"w": 6.5}, {}, "'w' must be an integer, got 6.5"),
    ({"h": 8}, {}, r"frame 0: 'h' = 8 but the image is 6x4"),
    ({}, {"transform_matrix": [["a"] * 4] * 4}, r"frame 0: 'transform_matrix' must be a 3x4 or "
                                                r"4x4 matrix of numbers"),
    ({}, {"transform_matrix": [[1, 0], [0, 1, 0]]}, r"'transform_matrix' must be a 3x4 or 4x4"),
    ({}, {"transform_matrix": (np.diag([1.0, 1, -1, 1])).tolist()}, "a reflection"),
    ({}, {"transform_matrix": "identity"}, "'transform_matrix' must be a 3x4 or 4x4 matrix"),
    ({}, {"file_path": 3}, "'file_path' must be a non-empty string"),
    ({}, {"depth_file_path": 3}, "'depth_file_path' must be a non-empty string"),
    ({"frames": {"file_path": "x"}}, {}, "missing or empty 'frames' list"),
    # Camera models a pinhole cannot reproduce are refused, not read as pinholes.
    ({"camera_model": "OPENCV", "k1": 0.1}, {}, r"transforms_train.json: distortion coefficient "
                                                r"'k1' = 0.1 \(camera model OPENCV\)"),
    ({"camera_model": "OPENCV"}, {"p2": -0.01}, r"frame 0: distortion coefficient 'p2' = -0.01"),
    ({}, {"k2": 0.02}, r"frame 0: distortion coefficient 'k2' = 0.02 \(camera model PINHOLE\)"),
    ({"camera_model": "OPENCV_FISHEYE"}, {}, r"'camera_model' is 'OPENCV_FISHEYE', which the "
                                             r"pinhole renderer cannot reproduce"),
    ({}, {"camera_model": 3}, "frame 0: 'camera_model' must be a string, got 3"),
    ({"k3": "0"}, {}, "'k3' must be a finite number, got '0'"),
    ({"camera_angle_x": None, "fl_y": 50.0}, {}, r"a vertical focal length \('fl_y' or "
                                                 r"'camera_angle_y'\) without a horizontal one"),
    ({"camera_angle_y": 4.0}, {}, r"'camera_angle_y' = 4.0 is not in \(0, pi\) radians"),
    ({}, {"name": 3}, "frame 0: 'name' must be a non-empty string, got 3"),
])
def test_blender_json_field_table(tmp_path, meta, frame, message):
  root = _blender(tmp_path, meta, frame)
  with pytest.raises(DatasetError, match=message):
    load_blender(root, "train")


@pytest.mark.parametrize("meta, frame, expected", [
    ({"camera_model": "OPENCV", "k1": 0.0, "k2": 0, "p1": 0.0, "p2": 0.0}, {},
     {"fx": 3.0 / np.tan(0.4), "fy": 3.0 / np.tan(0.4)}),  # zero distortion: a pinhole
    ({"camera_angle_y": 0.6}, {}, {"fx": 3.0 / np.tan(0.4), "fy": 2.0 / np.tan(0.3)}),
    ({"fl_y": 7.5}, {}, {"fx": 3.0 / np.tan(0.4), "fy": 7.5}),  # fl_y beside camera_angle_x
    ({"fl_x": 9.0}, {"fl_y": 8.0}, {"fx": 9.0, "fy": 8.0}),
    ({"fl_x": 9.0}, {}, {"fx": 9.0, "fy": 9.0}),  # square pixels
])
def test_blender_intrinsics_per_axis(tmp_path, meta, frame, expected):
  """Per axis: the focal length, else the field of view over the image size (6 x 4 here);
  no vertical one: fy = fx."""
  cameras = load_blender(_blender(tmp_path, meta, frame), "train").cameras
  for key, value in expected.items():
    np.testing.assert_allclose(float(getattr(cameras, key)[0]), value, rtol=1e-6)


def _two_frames(tmp_path, second):
  root = _blender(tmp_path)
  meta = json.loads((root / "transforms_train.json").read_text())
  meta["frames"].append({**meta["frames"][0], **second})
  (root / "transforms_train.json").write_text(json.dumps(meta))
  return root


@pytest.mark.parametrize("second, message", [
    ({}, r"frame 1: the image .*r_0.png is also that of frame 0; every frame must be a distinct"),
    ({"file_path": "./train/r_0.png"}, r"frame 1: the image .*r_0.png is also that of frame 0"),
    ({"file_path": "./train/r_1", "name": "train/r_0"},
     r"frame 1: the view name 'train/r_0' is also that of frame 0"),
])
def test_blender_duplicate_frames_are_refused(tmp_path, second, message):
  root = _two_frames(tmp_path, second)
  Image.fromarray(np.zeros((4, 6, 4), np.uint8)).save(root / "train" / "r_1.png")
  with pytest.raises(DatasetError, match=message):
    load_blender(root, "train")


def test_blender_reads_an_absolute_file_path(tmp_path):
  """The image of an absolute `file_path` is read, and the view named by that path."""
  elsewhere = tmp_path / "elsewhere"
  elsewhere.mkdir()
  Image.fromarray(np.full((4, 6, 4), 255, np.uint8)).save(elsewhere / "x.png")
  (tmp_path / "data").mkdir()
  root = _two_frames(tmp_path / "data", {"file_path": str(elsewhere / "x.png")})
  views = load_blender(root, "train")
  assert views.names == ("train/r_0", (elsewhere / "x").as_posix())
  assert views.images[1].min() == 1.0


@pytest.mark.parametrize("text, message", [
    ('{"camera_angle_x": 0.8, "camera_angle_x": 0.9, "frames": []}',
     "the key 'camera_angle_x' appears twice in one json object"),
    ("[" * 100_000 + "]" * 100_000, "json nested too deeply"),
])
def test_json_that_a_reader_would_misread_is_refused(tmp_path, text, message):
  (tmp_path / "t.json").write_text(text)
  with pytest.raises(DatasetError, match=rf"t.json: {message}"):
    read_json(tmp_path / "t.json")


def test_blender_reads_16_bit_images_at_full_precision(tmp_path):
  root = _blender(tmp_path)
  values = np.random.default_rng(0).integers(0, 65536, (4, 6, 4), np.uint16)
  values[..., 3] = 65535  # opaque: the composite is the stored colour
  _png(root / "train" / "r_0.png", values)
  views = load_blender(root, "train")
  np.testing.assert_allclose(views.images[0], values[..., :3] / 65535.0, atol=1e-7)


@pytest.mark.parametrize("array, message", [
    (np.array([{"pose": 1}], dtype=object), "cannot read"),  # pickled objects are refused
    (np.zeros((2, 17), np.complex64), "expected a real number array, got dtype complex64"),
    (np.full((2, 17), "1.0"), "expected a real number array, got dtype <U3"),
    (np.zeros((2, 16)), r"expected an array of shape \[V, 17\]"),
    ({"poses": np.zeros((2, 17))}, r"an .npz archive, not a .npy array"),
])
def test_llff_poses_file_table(tmp_path, array, message):
  (tmp_path / "images_8").mkdir()
  if isinstance(array, dict):  # np.savez to a file object keeps the .npy name
    with open(tmp_path / "poses_bounds.npy", "wb") as f:
      np.savez(f, **array)
  else:
    np.save(tmp_path / "poses_bounds.npy", array, allow_pickle=True)
  with pytest.raises(DatasetError, match=rf"poses_bounds.npy: .*{message}"):
    load_llff(tmp_path)


@pytest.mark.parametrize("files, message", [
    ({"a.png": (16, 16), "a.jpg": (16, 16)}, r"images_8: two views have the file stem 'a'"),
    ({"a.png": (16, 16), "b.png": (16, 8)}, r"b.png: image is 8x16 but a.png is 16x16"),
    ({"a.png": (16, 8), "b.png": (16, 8)}, r"a.png: image is 8x16, not a scaled copy of the "
                                           r"16x16 that .*poses_bounds.npy row 0 was calibrated"),
])
def test_llff_images_table(tmp_path, files, message):
  cams = Camera.create(np.stack([W2C] * 2), 8.0, 8.0, 8.0, 8.0, 16, 16)
  np.save(tmp_path / "poses_bounds.npy", poses_bounds_from_cameras(cams, [[1.0, 5.0]] * 2))
  (tmp_path / "images_8").mkdir()
  for name, (h, w) in files.items():
    Image.fromarray(np.zeros((h, w, 3), np.uint8)).save(tmp_path / "images_8" / name)
  with pytest.raises(DatasetError, match=message):
    load_llff(tmp_path)


# ---------------------------------------------------------------------- COLMAP models

IMAGES_AB = ((1, (1.0, 0.0, 0.0, 0.0), "a.png"), (2, (1.0, 0.0, 0.0, 0.0), "b.png"))


def _colmap_binary(root, cameras=((1, 1, 40, 30, (50.0, 60.0, 20.0, 15.0)),), images=IMAGES_AB,
                   points=((1, (0.1, 0.2, 0.3), 1), (2, (0.0, 0.1, 0.2), 0))):
  """A COLMAP sparse model written byte by byte in the documented binary layout (without the
  rigs and frames of COLMAP 3.12+, which pycolmap then makes one per camera and image), and a
  40 x 30 image per name.

  cameras: (id, model id, width, height, params); images: (id, (qw, qx, qy, qz), name), each
  at t = (0, 0, 2) with camera 1 and one 2D point; points: (id, xyz, track length), each
  track element (image 1, 2D point 0).
  """
  sparse = root / "sparse" / "0"
  sparse.mkdir(parents=True, exist_ok=True)
  count = lambda items: struct.pack("<Q", len(items))
  (sparse / "cameras.bin").write_bytes(count(cameras) + b"".join(
      struct.pack("<IiQQ", i, m, w, h) + struct.pack(f"<{len(ps)}d", *ps)
      for i, m, w, h, ps in cameras))
  (sparse / "images.bin").write_bytes(count(images) + b"".join(
      struct.pack("<I4d3dI", i, *q, 0.0, 0.0, 2.0, 1) + name.encode() + b"\0"
      + struct.pack("<Qddq", 1, 5.0, 5.0, -1) for i, q, name in images))
  (sparse / "points3D.bin").write_bytes(count(points) + b"".join(
      struct.pack("<Q3d3BdQ", i, *xyz, 200, 100, 50, 0.5, t) + struct.pack("<II", 1, 0) * t
      for i, xyz, t in points))
  (root / "images").mkdir(exist_ok=True)
  for _, _, name in images:
    Image.fromarray(np.zeros((30, 40, 3), np.uint8)).save(root / "images" / name)
  return root


def _cut(name, n):
  def damage(sparse):
    data = (sparse / name).read_bytes()
    (sparse / name).write_bytes(data[:-n])
  return damage


def _patch(name, offset, value):
  def damage(sparse):
    data = bytearray((sparse / name).read_bytes())
    data[offset:offset + len(value)] = value
    (sparse / name).write_bytes(bytes(data))
  return damage


IMAGE_RECORD = 4 + 56 + 4 + len("a.png\0") + 8 + 24  # images.bin: one image with one 2D point
COLMAP_FILES_BAD = {  # damage to the model of `_colmap_binary`: the expected message
    "points3D.bin 7 bytes short": (_cut("points3D.bin", 7),
                                   r"points3D.bin: truncated: 3D point record 1 \(51 bytes"),
    "points3D.bin 1 byte short": (_cut("points3D.bin", 1), r"points3D.bin: truncated: 3D point"),
    "a track of 10^12 elements": (_patch("points3D.bin", 8 + 43, struct.pack("<Q", 10 ** 12)),
                                  r"the track of 3D point record 0 runs past the end"),
    "10^15 points declared": (_patch("points3D.bin", 0, struct.pack("<Q", 10 ** 15)),
                              r"declares 1000000000000000 3D points of at least 51 bytes"),
    "bytes after the last point": (lambda sp: open(sp / "points3D.bin", "ab").write(b"\0" * 9),
                                   "9 bytes follow the last of the 3D points"),
    "an empty points3D.bin": (lambda sp: (sp / "points3D.bin").write_bytes(b""),
                              "points3D.bin: the file is empty"),
    "images.bin cut in a name": (
        lambda sp: (sp / "images.bin").write_bytes((sp / "images.bin").read_bytes()[
            :8 + IMAGE_RECORD + 66]),
        "the name of image 2 has no terminating NUL byte"),
    "10^12 2D points declared": (
        _patch("images.bin", 8 + 64 + 6, struct.pack("<Q", 10 ** 12)),
        r"images.bin: truncated: the 1000000000000 2D points of image 'a.png'"),
    "an image of a missing camera": (_patch("images.bin", 8 + 60, struct.pack("<I", 7)),
                                     r"image 1 \('a.png'\) refers to camera 7, which "
                                     "cameras.bin does not hold"),
    "cameras.bin cut in the parameters": (_cut("cameras.bin", 5),
                                          r"cameras.bin: truncated: the 4 parameters of camera 1"),
    "an unknown camera model": (_patch("cameras.bin", 12, struct.pack("<i", 99)),
                                "camera 1 has the model id 99, which COLMAP does not define"),
}


@pytest.mark.parametrize("case", COLMAP_FILES_BAD)
def test_colmap_binary_files_are_walked_before_pycolmap(tmp_path, case):
  """pycolmap trusts the counts: on these files it exhausts the memory, loops for ever or
  reads leftover values. The walk refuses them first, naming the file and the record."""
  pytest.importorskip("pycolmap")
  root = _colmap_binary(tmp_path)
  damage, message = COLMAP_FILES_BAD[case]
  damage(root / "sparse" / "0")
  with pytest.raises(DatasetError, match=message):
    load_colmap(root)


@pytest.mark.parametrize("name, cut", [("frames.bin", 3), ("rigs.bin", 3)])
def test_colmap_rigs_and_frames_files_are_walked_too(tmp_path, name, cut):
  """The rigs.bin and frames.bin that COLMAP 3.12+ (and pycolmap's writer) add."""
  pytest.importorskip("pycolmap")
  cams = Camera.create(np.stack([W2C] * 2), 6.0, 6.0, 4.0, 4.0, 8, 8)
  sparse = export_colmap(tmp_path, Views(np.zeros((2, 8, 8, 3), np.float32), cams))
  load_colmap(tmp_path)
  _cut(name, cut)(sparse)
  with pytest.raises(DatasetError, match=rf"{name}: truncated"):
    load_colmap(tmp_path)


Q0 = (0.0, 0.0, 0.0, 0.0)
COLMAP_FIELDS_BAD = {  # _colmap_binary arguments: the expected message
    "a zero quaternion": ({"images": ((1, Q0, "a.png"), IMAGES_AB[1])},
                          r"image 'a.png': the rotation quaternion \(qw, qx, qy, qz\) = "
                          r"\[0.0, 0.0, 0.0, 0.0\] has norm 0"),
    "a quaternion of norm 2": ({"images": ((1, (2.0, 0, 0, 0), "a.png"), IMAGES_AB[1])},
                               "has norm 2; COLMAP stores unit quaternions"),
    "an image listed twice": ({"images": (IMAGES_AB[0], (2, (1.0, 0, 0, 0), "a.png"))},
                              "the image 'a.png' is listed twice; view names must be unique"),
    "a.png and a.jpg": ({"images": (IMAGES_AB[0], (2, (1.0, 0, 0, 0), "a.jpg"))},
                        "the images 'a.jpg' and 'a.png' both give the view name 'a'"),
    "camera width 0": ({"cameras": ((1, 1, 0, 30, (50.0, 60.0, 20.0, 15.0)),)},
                       r"camera 1 \(used by image 'a.png'\): invalid image size width=0"),
    "a NaN 3D point": ({"points": ((1, (0.1, NAN, 0.3), 0),)}, "3D point 1 is not finite"),
}


@pytest.mark.parametrize("case", COLMAP_FIELDS_BAD)
def test_colmap_model_field_table(tmp_path, case):
  pytest.importorskip("pycolmap")
  kwargs, message = COLMAP_FIELDS_BAD[case]
  with pytest.raises(DatasetError, match=message):
    load_colmap(_colmap_binary(tmp_path, **kwargs))


COLMAP_TEXT_BAD = {  # (cameras.txt, images.txt pose lines, points3D.txt): the expected message
    "a name with a space": ("1 PINHOLE 40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 1 my a.png"], "",
                            r"images.txt line 1: the image name 'my a.png' contains a space"),
    "colour 300": ("1 PINHOLE 40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 1 a.png"],
                   "4 1 2 3 300 128 0 0.5", r"points3D.txt line 1: colour R = 300 is outside "
                                            r"0..255"),
    "an image of a missing camera": ("1 PINHOLE 40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 3 a.png"],
                                     "", "image 'a.png' refers to camera 3, which cameras.txt"),
    "width -40": ("1 PINHOLE -40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 1 a.png"], "",
                  "invalid image size width=18446744073709551576"),
    "a line pycolmap cannot parse": ("1 PINHOLE 40 30 50 60 20 15", ["1 1 0 0 0 0 0 2 1 a.png"],
                                     "4 1 x 3 255 128 0 0.5", "cannot read the COLMAP model"),
}


@pytest.mark.parametrize("case", COLMAP_TEXT_BAD)
def test_colmap_text_model_table(tmp_path, case):
  pytest.importorskip("pycolmap")
  camera, images, points, message = COLMAP_TEXT_BAD[case]
  sparse = tmp_path / "sparse" / "0"
  sparse.mkdir(parents=True)
  (sparse / "cameras.txt").write_text(camera + "\n")
  (sparse / "images.txt").write_text("".join(line + "\n\n" for line in images))
  (sparse / "points3D.txt").write_text(points + "\n")
  (tmp_path / "images").mkdir()
  Image.fromarray(np.zeros((30, 40, 3), np.uint8)).save(tmp_path / "images" / "a.png")
  with pytest.raises(DatasetError, match=message):
    load_colmap(tmp_path)


# ---------------------------------------------------------------------- .ply headers

PLY_PROPERTIES = "".join(f"property float {p}\n" for p in (
    "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
    "rot_0", "rot_1", "rot_2", "rot_3"))


@pytest.mark.parametrize("header, data, message", [
    ("format binary_little_endian 1.0\nelement vertex 100000000000\n" + PLY_PROPERTIES,
     b"\0" * 60, "truncated: the header declares 100000000000 vertex rows of 56 bytes, but the "
                 "data ends in row 1, at property 'y'"),
    ("format ascii 1.0\nelement vertex 100000000000\n" + PLY_PROPERTIES, b"1 2 3\n",
     "ASCII PLY"),
    ("format binary_little_endian 1.0\nelement face 10000000000\nproperty list uchar int idx\n"
     "element vertex 1\n" + PLY_PROPERTIES, b"\0" * 60,
     "truncated: the header declares 10000000000 face rows of at least 1 bytes"),
], ids=["10^11 vertices", "ascii", "10^10 list rows"])
def test_ply_headers_are_checked_against_the_file_before_reading(tmp_path, header, data, message):
  """plyfile allocates the rows a header declares before reading them (terabytes here)."""
  path = tmp_path / "bad.ply"
  path.write_bytes(b"ply\n" + header.encode() + b"end_header\n" + data)
  with pytest.raises(DatasetError, match=rf"bad.ply: {message}"):
    load_ply(path)


# ---------------------------------------------------------------------- Views, exports

VIEWS = Views(np.zeros((2, 8, 8, 3), np.float32),
              Camera.create(np.stack([W2C] * 2), 6.0, 6.0, 4.0, 4.0, 8, 8), names=("a", "b"))


@pytest.mark.parametrize("changes, message", [
    ({"names": ("a", "a")}, "Views.names repeats 'a'"),
    ({"names": ("a",)}, r"Views.names must hold 2 names \(one per view\) or none, got 1"),
    ({"alphas": np.ones((2, 8, 7))}, r"Views.alphas must have shape \[2, 8, 8\]"),
    ({"images": np.zeros((2, 8, 8, 3), np.uint8)}, "Views.images must be floats"),
    ({"cameras": Camera.create(W2C, 6.0, 6.0, 4.0, 4.0, 8, 8)},
     r"Views.cameras must be a Camera batched over \[2\] .*got batch \(\)"),
])
@pytest.mark.parametrize("export", ["blender", "colmap"])
def test_views_are_checked_before_export(tmp_path, changes, message, export):
  views = VIEWS.replace(**changes)
  with pytest.raises(ValueError, match=message):
    views.validate()
  if export == "colmap":
    pytest.importorskip("pycolmap")
  with pytest.raises(ValueError, match=message):
    (export_blender if export == "blender" else export_colmap)(tmp_path, views)
  assert not any(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize("cameras, bounds, message", [
    (VIEWS.cameras, np.ones((3, 2)), r"bounds must have shape \[V=2, 2\] \(near, far\)"),
    (Camera.create(np.stack([W2C] * 2), 6.0, 7.0, 4.0, 4.0, 8, 8), np.ones((2, 2)),
     r"cameras.fy\[0\] = 7.0, but LLFF stores one focal length .*: it must be 6.0"),
    (Camera.create(np.stack([W2C] * 2), 6.0, 6.0, 4.0, [4.0, 3.5], 8, 8), np.ones((2, 2)),
     r"cameras.cy\[1\] = 3.5, .* it must be 4.0"),
])
def test_llff_poses_are_written_only_when_the_format_holds_them(cameras, bounds, message):
  with pytest.raises(ValueError, match=message):
    poses_bounds_from_cameras(cameras, bounds)


def test_export_colmap_checks_its_points(tmp_path):
  pytest.importorskip("pycolmap")
  with pytest.raises(ValueError, match=r"points must hold xyz \[P, 3\] and rgb \[P, 3\]"):
    export_colmap(tmp_path, VIEWS, PointCloud(np.zeros((3, 3)), np.zeros((2, 3))))
  with pytest.raises(ValueError, match=r"points.xyz\[1\] is not finite"):
    export_colmap(tmp_path, VIEWS, PointCloud(np.array([[0, 0, 0], [NAN, 0, 0]]),
                                              np.zeros((2, 3))))
  with pytest.raises(ValueError, match=r"percentile must be a number in \[0, 50\)"):
    PointCloud(np.zeros((3, 3)), np.zeros((3, 3))).box(60)
