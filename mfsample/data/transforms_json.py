"""The camera fields of a `transforms.json` (NeRF Synthetic, instant-ngp, nerfstudio).

One frame's camera is read from its own keys, falling back to the file's top-level keys (a
per-frame key overrides the top-level one; errors name where the value came from):

* intrinsics in pixels of the full-size image: `fl_x`, `fl_y`, `cx`, `cy`, `w`, `h`, or the
  fields of view `camera_angle_x`, `camera_angle_y` (radians). Per axis: the focal length
  when given, else the field of view over the image size; `fl_y` and `camera_angle_y` absent,
  fy = fx (square pixels). A vertical focal length without a horizontal one (`fl_y` alone) is
  refused: the image's horizontal scale would be a guess. `cx`, `cy` default to the image
  centre; `w`, `h` must equal the image's size.
* the camera model: `camera_model` (nerfstudio; absent: a perspective camera) and the
  distortion coefficients `k1`..`k4`, `p1`, `p2` or a `distortion_params` list. The pinhole
  renderer reproduces only perspective cameras without distortion: SIMPLE_PINHOLE, PINHOLE,
  and SIMPLE_RADIAL, RADIAL, OPENCV whose coefficients are all 0. A fisheye, equirectangular
  or distorted camera is refused, naming the model or the coefficient, rather than read as a
  pinhole.
* plausible pinhole intrinsics (`check_pinhole`): focal lengths between `MIN_FOCAL` and
  `MAX_FOCAL` times the image size and the principal point inside the image; anything else is
  a unit mistake (values normalised by the image size, millimetres) more often than a lens.
* `mask_path` (nerfstudio's per-frame masks) is refused (`refuse_masks`): the training loss
  has no mask, so masked pixels would be fitted as they are.
"""

import numpy as np

from mfsample.data import _io

DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")
# nerfstudio's perspective camera models (its others: OPENCV_FISHEYE, EQUIRECTANGULAR, ...).
PERSPECTIVE_MODELS = ("SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV")

# Plausible focal lengths, as multiples of the image's width (fx) or height (fy): 0.05 is a
# field of view of 2 atan(10) = 168.6 degrees, wider than any undistorted photograph; 1000 is
# 0.057 degrees, narrower than a telescope's eyepiece view. Outside: a unit mistake.
MIN_FOCAL = 0.05
MAX_FOCAL = 1000.0

_UNDISTORT_HINT = ("undistort the images first (e.g. nerfstudio's ns-process-data with "
                   "COLMAP's image_undistorter, or OpenCV's cv2.undistort / "
                   "cv2.fisheye.undistortImage) and write the pinhole intrinsics they give")


class FrameFields:
  """The keys of one frame with the file's top-level keys as fallback.

  Args:
    meta: the json object of the file.
    frame: the json object of the frame.
    where: text naming the file and frame in messages ("transforms.json frame 3").
    json_path: the file (names top-level values in messages).
  """

  def __init__(self, meta, frame, where, json_path):
    self.meta, self.frame, self.where, self.json_path = meta, frame, where, str(json_path)

  def at(self, key):
    """Where `key` comes from: the frame's text when it has the key, else the file's."""
    return self.where if key in self.frame else self.json_path

  def raw(self, key):
    return self.frame[key] if key in self.frame else self.meta.get(key)

  def number(self, key, *, integer=False):
    """The value of `key` as a finite float (an int when `integer`), or None when absent
    (or null); DatasetError naming where it came from otherwise."""
    mapping = self.frame if key in self.frame else self.meta
    if mapping.get(key) is None:
      return None
    return _io.number(mapping, key, self.at(key), integer=integer)


def camera_model(fields: FrameFields):
  """The frame's camera model name after checking that a pinhole reproduces it.

  Raises:
    DatasetError: a model other than `PERSPECTIVE_MODELS`, a non-zero or non-numeric
      distortion coefficient (naming it), a `camera_model` that is not a string.
  """
  model = fields.raw("camera_model")
  if model is None:
    model = "PINHOLE"
  elif not isinstance(model, str):
    raise _io.DatasetError(f"{fields.at('camera_model')}: 'camera_model' must be a string, "
                           f"got {model!r}.")
  if model not in PERSPECTIVE_MODELS:
    raise _io.DatasetError(
        f"{fields.at('camera_model')}: 'camera_model' is {model!r}, which the pinhole "
        f"renderer cannot reproduce (it reads {', '.join(PERSPECTIVE_MODELS)} without "
        f"distortion); {_UNDISTORT_HINT}.")
  for key in DISTORTION_KEYS:
    value = fields.number(key)
    if value:  # not None, not 0
      raise _io.DatasetError(
          f"{fields.at(key)}: distortion coefficient '{key}' = {value} (camera model "
          f"{model}); the pinhole renderer needs undistorted images: {_UNDISTORT_HINT}.")
  # A list in the frame and one at the top level: both must be zero (either could be read).
  for where, mapping in ((fields.where, fields.frame), (fields.json_path, fields.meta)):
    listed = distortion_list(mapping.get("distortion_params"), where)
    if any(listed):
      raise _io.DatasetError(
          f"{where}: 'distortion_params' = {listed} (camera model {model}); the pinhole "
          f"renderer needs undistorted images: {_UNDISTORT_HINT}.")
  return model


def distortion_list(value, where, key="distortion_params"):
  """The coefficients of a `distortion_params` list as floats ([] when absent or null).

  Raises:
    DatasetError: naming `where` and `key` when it is not a list of finite numbers.
  """
  if value is None:
    return []
  ok = isinstance(value, list) and all(
      isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
      for v in value)
  if not ok:
    raise _io.DatasetError(f"{where}: '{key}' must be a list of finite numbers, got "
                           f"{_io.short(value)}.")
  return [float(v) for v in value]


def refuse_masks(mapping, where):
  """DatasetError when `mapping` (a frame or the file) carries `mask_path`: the training loss
  has no per-pixel mask, so the masked pixels would be fitted as they are."""
  if mapping.get("mask_path") is not None:
    raise _io.DatasetError(
        f"{where}: 'mask_path' = {_io.short(mapping['mask_path'])}: masks are not supported "
        "(training fits every pixel, so masked pixels would be fitted as they are); remove "
        "the 'mask_path' keys to train on every pixel, or crop or inpaint the masked regions.")


def check_pinhole(where, width, height, fx, fy, cx, cy, keys=("fl_x", "fl_y", "cx", "cy")):
  """Refuses intrinsics no photograph has (see `MIN_FOCAL`, `MAX_FOCAL`).

  Args:
    where: names the file and frame in messages.
    width, height: the size (pixels) the intrinsics are calibrated for.
    fx, fy, cx, cy: the intrinsics in pixels of that size.
    keys: the names of fx, fy, cx, cy in the file (for messages).

  Raises:
    DatasetError: a focal length <= 0, under `MIN_FOCAL` or over `MAX_FOCAL` times the image
      size along its axis, or a principal point outside [0, width] x [0, height]; naming the
      key and its value.
  """
  if fx <= 0 or fy <= 0:
    raise _io.DatasetError(f"{where}: focal lengths must be > 0, got {keys[0]}={fx}, "
                           f"{keys[1]}={fy}.")
  for key, focal, size, side in ((keys[0], fx, width, "width"), (keys[1], fy, height, "height")):
    if focal < MIN_FOCAL * size:
      raise _io.DatasetError(
          f"{where}: '{key}' gives a focal length of {focal:g} pixels, under {MIN_FOCAL:g} x "
          f"the image {side} "
          f"({size} pixels; a field of view over 168 degrees): are the intrinsics normalised "
          "by the image size? They must be in pixels.")
    if focal > MAX_FOCAL * size:
      raise _io.DatasetError(
          f"{where}: '{key}' gives a focal length of {focal:g} pixels, over {MAX_FOCAL:g} x "
          f"the image {side} "
          f"({size} pixels; a field of view under 0.06 degrees): the intrinsics must be in "
          "pixels of the image.")
  for key, centre, size in ((keys[2], cx, width), (keys[3], cy, height)):
    if not 0.0 <= centre <= size:
      raise _io.DatasetError(f"{where}: '{key}' = {centre:g} lies outside the image (0 .. "
                             f"{size} pixels); the principal point must be in pixels of the "
                             "image.")


def intrinsics(fields: FrameFields, size):
  """[4] float64 (fx, fy, cx, cy) in pixels of the full-size image [height, width] `size`,
  after `camera_model` (see the module docstring for the rules).

  Raises:
    DatasetError: naming the key and where it came from.
  """
  camera_model(fields)
  refuse_masks(fields.frame, fields.where)
  refuse_masks(fields.meta, fields.json_path)
  height, width = size
  for key, expected in (("w", width), ("h", height)):
    got = fields.number(key, integer=True)
    if got is not None and got != expected:
      raise _io.DatasetError(f"{fields.where}: '{key}' = {got} but the image is "
                             f"{width}x{height}.")
  fx, fx_key = _focal(fields, "fl_x", "camera_angle_x", width)
  if fx is None:
    if fields.raw("fl_y") is not None or fields.raw("camera_angle_y") is not None:
      raise _io.DatasetError(f"{fields.where}: a vertical focal length ('fl_y' or "
                             "'camera_angle_y') without a horizontal one: 'fl_x' or "
                             "'camera_angle_x' is missing.")
    raise _io.DatasetError(f"{fields.where}: missing key 'camera_angle_x' (or 'fl_x').")
  fy, fy_key = _focal(fields, "fl_y", "camera_angle_y", height)
  if fy is None:
    fy, fy_key = fx, fx_key
  cx, cy = fields.number("cx"), fields.number("cy")
  cx = 0.5 * width if cx is None else cx
  cy = 0.5 * height if cy is None else cy
  check_pinhole(fields.where, width, height, fx, fy, cx, cy, (fx_key, fy_key, "cx", "cy"))
  return np.array([fx, fy, cx, cy])


def _focal(fields, focal_key, angle_key, pixels):
  """(focal length along one axis, the key it came from): `focal_key`, else from the field
  of view `angle_key` over `pixels`, else (None, None)."""
  focal = fields.number(focal_key)
  if focal is not None:
    return focal, focal_key
  angle = fields.number(angle_key)
  if angle is None:
    return None, None
  if not 0.0 < angle < np.pi:
    raise _io.DatasetError(f"{fields.at(angle_key)}: '{angle_key}' = {angle} is not in "
                           "(0, pi) radians.")
  return 0.5 * pixels / np.tan(0.5 * angle), angle_key
