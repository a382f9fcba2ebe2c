"""Shared helpers of the dataset loaders: errors that name the file, image I/O, pose checks.

Everything here runs on the host in numpy (float64 where precision matters); loaders convert
to float32 / `Camera` at the end.
"""

import json
import os
from pathlib import Path

import numpy as np
from PIL import Image

from mfsample import fingerprints

# A rotation is accepted when |R^T R - I| and |det R - 1| stay below this. Dataset poses are
# stored as float32 (lego: errors ~1e-7); anything near 1e-3 is a scaled or sheared matrix.
ROTATION_TOLERANCE = 1e-3

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


class DatasetError(ValueError):
  """A dataset file exists but its content is unusable (the message names the file)."""


def resolve_path(path):
  """`path` with `~` expanded, made absolute (relative paths: to the working directory)."""
  return Path(os.path.expanduser(str(path))).resolve()


def require_dir(path, what="dataset folder"):
  path = Path(path)
  if not path.is_dir():
    raise FileNotFoundError(f"{what} not found: {path}")
  return path


def require_file(path, what="file"):
  """`path`, a file about to be read as an input: announced to the recordings of a run's
  inputs (`mfsample.fingerprints.note`). FileNotFoundError naming `what` when absent."""
  path = Path(path)
  if not path.is_file():
    raise FileNotFoundError(f"{what} not found: {path}")
  fingerprints.note(path)
  return path


def read_json(path):
  """Parses a json file; DatasetError with the file and position when malformed."""
  path = require_file(path, "json file")

  def unique_keys(pairs):
    seen = set()
    for key, _ in pairs:
      if key in seen:
        raise DatasetError(f"{path}: the key {key!r} appears twice in one json object (a "
                           "json reader keeps one of the two silently).")
      seen.add(key)
    return dict(pairs)

  try:
    with open(path, encoding="utf-8") as f:
      return json.load(f, object_pairs_hook=unique_keys)
  except json.JSONDecodeError as e:
    raise DatasetError(f"{path}: malformed json ({e.msg} at line {e.lineno}, column "
                       f"{e.colno}).") from e
  except UnicodeDecodeError as e:
    raise DatasetError(f"{path}: not a UTF-8 text file ({e}).") from e
  except RecursionError as e:
    raise DatasetError(f"{path}: json nested too deeply to read (thousands of levels): not a "
                       "dataset file.") from e


def read_image(path):
  """Reads an image as float32 in [0, 1], at the full precision of the file.

  Args:
    path: a PNG (1, 2, 4, 8 or 16 bits per channel; grey, grey + alpha, RGB, RGBA or a
      palette) or a JPEG (grey, RGB or CMYK) file.

  Returns:
    ([H, W, 3] colour, [H, W] alpha or None when the file has no alpha channel). The colour is
    the stored (straight, not premultiplied) colour. Float images (a 32-bit float TIFF) are
    read as stored.

  Raises:
    DatasetError: the file is not a readable image of those kinds, or holds float values that
      are not finite or outside [0, 1] (naming the file).
  """
  path = require_file(path, "image")
  try:
    if _png_header(path)[0] == 16:  # Pillow would round 16-bit colour to 8 bits
      data = _read_png16(path)
    else:
      with Image.open(path) as image:
        data = _pillow_array(image, path)
  except DatasetError:
    raise
  except Exception as e:  # Pillow and pypng raise their own types for corrupt files
    raise DatasetError(f"{path}: cannot read image ({type(e).__name__}: {e}).") from e
  if data.dtype == np.uint8:
    img = data.astype(np.float32) / 255.0
  elif data.dtype == np.uint16:
    img = data.astype(np.float32) / 65535.0
  elif data.dtype == np.bool_:
    img = data.astype(np.float32)
  elif np.issubdtype(data.dtype, np.floating):
    img = data.astype(np.float32)
    # Float pixels (a TIFF of mode F) are used as stored: they must already be in [0, 1].
    if not np.all(np.isfinite(img)):
      raise DatasetError(f"{path}: {np.count_nonzero(~np.isfinite(img))} pixel values are NaN "
                         "or infinite; images must hold finite values.")
    if img.size and (img.min() < 0.0 or img.max() > 1.0):
      raise DatasetError(f"{path}: float pixel values span {img.min():g} .. {img.max():g}; a "
                         "float image must hold values in [0, 1] (8-bit values stored as "
                         "floats would be read as white).")
  else:
    raise DatasetError(f"{path}: unsupported pixel type {data.dtype}.")
  if img.ndim == 2:
    img = img[..., None]
  if img.ndim != 3 or img.shape[-1] not in (1, 2, 3, 4):
    raise DatasetError(f"{path}: expected a grey, grey+alpha, RGB or RGBA image, got an "
                       f"array of shape {data.shape}.")
  channels = img.shape[-1]
  alpha = img[..., -1] if channels in (2, 4) else None
  color = img[..., :3] if channels >= 3 else np.repeat(img[..., :1], 3, axis=-1)
  return np.ascontiguousarray(color), alpha


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_header(path):
  """(bit depth, colour type) of a PNG file's IHDR, or (None, None) for other files."""
  with open(path, "rb") as f:
    head = f.read(26)
  if len(head) < 26 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
    return None, None
  return head[24], head[25]


def png_bit_depth(path):
  """Bits per channel of a PNG file (1-16), or None for a file that is not a PNG."""
  return _png_header(path)[0]


def _read_png16(path):
  """[H, W, C] uint16 of a 16-bit PNG (pypng: exact; tRNS becomes an alpha channel)."""
  try:
    import png
  except ImportError as err:
    raise ImportError(f"{path} is a 16-bit PNG; reading it at full precision needs pypng "
                      "(pip install pypng).") from err
  width, height, rows, info = png.Reader(filename=str(path)).asDirect()
  planes = int(info["planes"])
  data = np.vstack([np.asarray(row, np.uint16) for row in rows])
  return data.reshape(height, width, planes)


def _pillow_array(image, path):
  """The pixels of a Pillow image as a numpy array in one of read_image's layouts."""
  mode = image.mode
  if mode == "P":  # palette: its colours (and transparency, if any)
    image = image.convert("RGBA" if "transparency" in image.info else "RGB")
  elif mode in ("CMYK", "YCbCr", "LAB", "HSV"):
    image = image.convert("RGB")
  elif mode == "1":
    image = image.convert("L")
  elif mode in ("I", "I;16", "I;16B", "I;16L"):  # 16-bit grey (or 32-bit int) files
    data = np.asarray(image)
    if data.min(initial=0) < 0 or data.max(initial=0) > 65535:
      raise DatasetError(f"{path}: integer pixels outside [0, 65535] (mode {mode}).")
    return data.astype(np.uint16)
  elif mode not in ("L", "LA", "RGB", "RGBA", "F"):
    raise DatasetError(f"{path}: unsupported image mode {mode!r}.")
  return np.asarray(image)


def image_scale(file, shape, first, calibrated, first_name, calibrated_for):
  """(sx, sy): an image's size over the size its camera was calibrated for.

  Args:
    file: the image file (for messages).
    shape: its (height, width).
    first: (height, width) of the capture's first image (all must share one size).
    calibrated: (width, height) of the camera's calibration.
    first_name: names the first image in the message.
    calibrated_for: names the camera in the message ("camera 1 of sparse/0").

  Raises:
    DatasetError: a size unlike the first image's, or not a scaled copy of the calibrated
      one. A resized copy keeps the aspect ratio up to rounding (or flooring) each side to
      whole pixels: one of the two scales then reproduces the other side within 2 pixels.
  """
  (h, w), (cam_w, cam_h) = shape, calibrated
  if tuple(shape) != tuple(first):
    raise DatasetError(f"{file}: image is {w}x{h} but {first_name} is {first[1]}x{first[0]}; "
                       "all images must share one size.")
  return check_scaled_copy(shape, (cam_h, cam_w), file, calibrated_for)


def area_downscale(x, factor, path=None):
  """Box-filters [H, W, ...] by an integer factor (H and W must be divisible by it).

  Averaging whole pixel blocks maps the continuous pixel coordinate p to p / factor exactly
  (pixel (i, j) covers [j, j + 1) x [i, i + 1)), so intrinsics scale by 1 / factor.
  """
  if factor == 1:
    return x
  h, w = x.shape[:2]
  if h % factor or w % factor:
    where = f"{path}: " if path is not None else ""
    raise DatasetError(f"{where}image size {w}x{h} is not divisible by downscale={factor}.")
  blocks = x.reshape(h // factor, factor, w // factor, factor, *x.shape[2:])
  return blocks.mean(axis=(1, 3), dtype=np.float64).astype(x.dtype)


def check_scaled_copy(image_size, calibrated_size, path, calibration):
  """(sx, sy): the scale of an image [height, width] against the [height, width] its camera
  was calibrated for; DatasetError unless it is a scaled copy (same aspect ratio, up to the
  rounding of each side to whole pixels: one scale reproduces the other side within 2
  pixels). `calibration` names where the calibrated size comes from."""
  (h, w), (cal_h, cal_w) = image_size, calibrated_size
  sx, sy = w / cal_w, h / cal_h
  if min(cal_w, cal_h) * abs(sx - sy) > 2.0:
    raise DatasetError(f"{path}: image is {w}x{h}, not a scaled copy of the {cal_w:g}x{cal_h:g} "
                       f"that {calibration} was calibrated for.")
  return sx, sy


def unique_names(names, where, what="view name"):
  """DatasetError naming the first repeated name (views are looked up by name)."""
  seen = set()
  for name in names:
    if name in seen:
      raise DatasetError(f"{where}: two views have the {what} {name!r}; names must be unique.")
    seen.add(name)


def check_downscale(downscale):
  if (not isinstance(downscale, (int, np.integer)) or isinstance(downscale, bool)
      or downscale < 1):
    raise ValueError(f"downscale must be an integer >= 1, got {downscale!r}")
  return int(downscale)


def validate_rigid(matrix, where, field="pose"):
  """Checks a [3, 4] or [4, 4] pose: finite, orthonormal rotation with det +1.

  Args:
    matrix: array-like pose.
    where: text naming the file and frame, used in the error message.
    field: what the matrix is called there ("'transform_matrix'").

  Returns:
    [4, 4] float64 matrix.
  """
  try:
    m = np.asarray(matrix, dtype=np.float64)
  except (TypeError, ValueError):
    raise DatasetError(f"{where}: {field} must be a 3x4 or 4x4 matrix of numbers, got "
                       f"{short(matrix)}.") from None
  if m.shape not in ((3, 4), (4, 4)):
    raise DatasetError(f"{where}: {field} must be a 3x4 or 4x4 matrix, got shape {m.shape}.")
  if not np.all(np.isfinite(m)):
    raise DatasetError(f"{where}: {field} has non-finite entries.")
  if m.shape == (3, 4):
    m = np.concatenate([m, [[0.0, 0.0, 0.0, 1.0]]], axis=0)
  elif np.max(np.abs(m[3] - [0.0, 0.0, 0.0, 1.0])) > ROTATION_TOLERANCE:
    raise DatasetError(f"{where}: {field} bottom row must be [0, 0, 0, 1], got "
                       f"{m[3].tolist()}.")
  rot = m[:3, :3]
  ortho_err = np.max(np.abs(rot.T @ rot - np.eye(3)))
  det = np.linalg.det(rot)
  if ortho_err > ROTATION_TOLERANCE or abs(det - 1.0) > ROTATION_TOLERANCE:
    mirror = "; a reflection" if det < 0 else ""
    raise DatasetError(f"{where}: {field} is not rigid (|R^T R - I| = {ortho_err:.2e}, "
                       f"det R = {det:.4f}{mirror}); expected a rotation and a translation.")
  m[3] = [0.0, 0.0, 0.0, 1.0]
  return m


def number(mapping, key, where, *, integer=False):
  """`mapping[key]` as a float (an int when `integer`); DatasetError naming `where` and the
  key when it is not a finite number (a string, a bool, a list, NaN)."""
  value = mapping[key]
  ok = isinstance(value, (int, float)) and not isinstance(value, bool)
  ok = ok and np.isfinite(value) and (not integer or float(value).is_integer())
  if not ok:
    kind = "an integer" if integer else "a finite number"
    raise DatasetError(f"{where}: '{key}' must be {kind}, got {short(value)}.")
  return int(value) if integer else float(value)


def short(value, limit=60):
  """repr(value), cut to `limit` characters (for messages)."""
  text = repr(value)
  return text if len(text) <= limit else text[:limit] + "..."


def invert_rigid(c2w):
  """[..., 4, 4] camera-to-world -> world-to-camera for rigid transforms (float64)."""
  c2w = np.asarray(c2w, dtype=np.float64)
  rot_t = np.swapaxes(c2w[..., :3, :3], -1, -2)
  out = np.zeros(c2w.shape, np.float64)
  out[..., :3, :3] = rot_t
  out[..., :3, 3] = -np.einsum("...ij,...j->...i", rot_t, c2w[..., :3, 3])
  out[..., 3, 3] = 1.0
  return out
