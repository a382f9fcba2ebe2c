"""The camera fields of a transforms.json (mfsample.data.transforms_json) as `load_blender`
reads them: every camera field is read or refused naming the file, the frame and the key."""

import json

import numpy as np
import pytest
from PIL import Image

from mfsample.data import DatasetError, load_blender
from mfsample.data.transforms_json import MAX_FOCAL, MIN_FOCAL

# A camera at z = 4 looking at the origin (OpenGL axes: it looks down its -z).
C2W = np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 4], [0, 0, 0, 1]])


def _blender(root, meta=None, frame=None):
  """One 32 x 24 frame with `meta` and `frame` keys added to the json's top level and frame."""
  (root / "train").mkdir(exist_ok=True)
  Image.fromarray(np.zeros((24, 32, 4), np.uint8)).save(root / "train" / "r_0.png")
  frames = [{"file_path": "./train/r_0", "transform_matrix": C2W.tolist(), **(frame or {})}]
  (root / "transforms_train.json").write_text(json.dumps({"camera_angle_x": 0.8,
                                                          "frames": frames, **(meta or {})}))
  return root


@pytest.mark.parametrize("meta, frame, message", [
    # distortion_params, at the top level or in a frame, like k1..p2.
    ({}, {"distortion_params": [0.1, 0, 0, 0]}, r"frame 0: 'distortion_params' = \[0.1, 0.0, "
                                                r"0.0, 0.0\] \(camera model PINHOLE\)"),
    ({"camera_model": "OPENCV", "distortion_params": [0, 0, 0, -0.01]}, {},
     r"transforms_train.json: 'distortion_params' = .* \(camera model OPENCV\)"),
    ({"distortion_params": "abc"}, {}, r"transforms_train.json: 'distortion_params' must be a "
                                       r"list of finite numbers, got 'abc'"),
    ({}, {"distortion_params": [0, None]}, r"frame 0: 'distortion_params' must be a list"),
    ({}, {"distortion_params": [0, float("nan")]}, r"'distortion_params' must be a list"),
    ({}, {"camera_model": "EQUIRECTANGULAR"}, r"frame 0: 'camera_model' is 'EQUIRECTANGULAR'"),
    # Masks cannot be honoured by the loss.
    ({}, {"mask_path": "./masks/r_0.png"}, r"frame 0: 'mask_path' = './masks/r_0.png': masks "
                                           r"are not supported"),
    ({"mask_path": "m.png"}, {}, r"transforms_train.json: 'mask_path' = 'm.png': masks are not"),
    # Intrinsics no photograph has, named with the key that gave them.
    ({"cx": -100.0}, {}, r"frame 0: 'cx' = -100 lies outside the image \(0 .. 32 pixels\)"),
    ({}, {"cy": 25.0}, r"frame 0: 'cy' = 25 lies outside the image \(0 .. 24 pixels\)"),
    ({"fl_x": 1e6}, {}, r"'fl_x' gives a focal length of 1e\+06 pixels, over 1000 x the image "
                        r"width \(32 pixels"),
    ({"fl_x": 0.8, "cx": 0.5, "cy": 0.5}, {}, r"'fl_x' gives a focal length of 0.8 pixels, under "
                                              r"0.05 x the image width .* normalised"),
    ({"fl_y": 1.0}, {}, r"'fl_y' gives a focal length of 1 pixels, under 0.05 x the image height"),
    ({"camera_angle_x": 3.1}, {}, r"'camera_angle_x' gives a focal length of 0.33.* pixels, under"),
    ({"camera_angle_x": 1e-6}, {}, r"'camera_angle_x' gives a focal length of 3.2e\+07 pixels"),
    ({"fl_x": 0.0}, {}, r"focal lengths must be > 0, got fl_x=0.0"),
])
def test_camera_fields_are_read_or_refused(tmp_path, meta, frame, message):
  with pytest.raises(DatasetError, match=message):
    load_blender(_blender(tmp_path, meta, frame), "train")


@pytest.mark.parametrize("meta, frame", [
    ({"distortion_params": [0.0, 0.0, 0.0, 0.0]}, {"distortion_params": []}),
    ({"camera_model": "OPENCV", "distortion_params": None}, {}),
    ({"cx": 0.0, "cy": 24.0}, {}),  # the principal point on the image's border
    ({"fl_x": MIN_FOCAL * 32, "fl_y": MAX_FOCAL * 24}, {}),  # the ends of the plausible range
])
def test_plausible_pinholes_are_read(tmp_path, meta, frame):
  cameras = load_blender(_blender(tmp_path, meta, frame), "train").cameras
  assert float(cameras.cx[0]) == meta.get("cx", 16.0)
  assert float(cameras.fx[0]) == pytest.approx(meta.get("fl_x", 16.0 / np.tan(0.4)), rel=1e-6)
