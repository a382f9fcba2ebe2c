"""Shared helpers of the dataset loaders: errors that name the file, image I/O, pose checks.

Everything here runs on the host in numpy (float64 where precision matters); loaders convert
to float32 / `Camera` at the end.
"""

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np

# A rotation is accepted when |R^T R - I| and |det R - 1| stay below this. Dataset poses are
# stored as float32 (lego: errors ~1e-7); anything near 1e-3 is a scaled or sheared matrix.
ROTATION_TOLERANCE = 1e-3

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


class DatasetError(ValueError):
  """A dataset file exists but its content is unusable (the message names the file)."""


def require_dir(path, what="dataset folder"):
  path = Path(path)
  if not path.is_dir():
    raise FileNotFoundError(f"{what} not found: {path}")
  return path


def require_file(path, what="file"):
  path = Path(path)
  if not path.is_file():
    raise FileNotFoundError(f"{what} not found: {path}")
  return path


def read_json(path):
  """Parses a json file; DatasetError with the file and position when malformed."""
  path = require_file(path, "json file")
  try:
    with open(path, encoding="utf-8") as f:
      return json.load(f)
  except json.JSONDecodeError as e:
    raise DatasetError(f"{path}: malformed json ({e.msg} at line {e.lineno}, column "
                       f"{e.colno}).") from e
  except UnicodeDecodeError as e:
    raise DatasetError(f"{path}: not a UTF-8 text file ({e}).") from e


def read_image(path):
  """Reads an image as float32 in [0, 1].

  Args:
    path: a PNG / JPEG file (8- or 16-bit; grey, grey + alpha, RGB or RGBA).

  Returns:
    ([H, W, 3] colour, [H, W] alpha or None when the file has no alpha channel). The colour is
    the stored (straight, not premultiplied) colour.
  """
  path = require_file(path, "image")
  try:
    data = iio.imread(path)
  except Exception as e:  # imageio raises plugin-specific types for corrupt files
    raise DatasetError(f"{path}: cannot read image ({e}).") from e
  if data.dtype == np.uint8:
    img = data.astype(np.float32) / 255.0
  elif data.dtype == np.uint16:
    img = data.astype(np.float32) / 65535.0
  elif np.issubdtype(data.dtype, np.floating):
    img = data.astype(np.float32)
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


def check_downscale(downscale):
  if (not isinstance(downscale, (int, np.integer)) or isinstance(downscale, bool)
      or downscale < 1):
    raise ValueError(f"downscale must be an integer >= 1, got {downscale!r}")
  return int(downscale)


def validate_rigid(matrix, where):
  """Checks a [3, 4] or [4, 4] pose: finite, orthonormal rotation with det +1.

  Args:
    matrix: array-like pose.
    where: text naming the file and frame, used in the error message.

  Returns:
    [4, 4] float64 matrix.
  """
  m = np.asarray(matrix, dtype=np.float64)
  if m.shape not in ((3, 4), (4, 4)):
    raise DatasetError(f"{where}: pose must be a 3x4 or 4x4 matrix, got shape {m.shape}.")
  if not np.all(np.isfinite(m)):
    raise DatasetError(f"{where}: pose has non-finite entries.")
  if m.shape == (3, 4):
    m = np.concatenate([m, [[0.0, 0.0, 0.0, 1.0]]], axis=0)
  elif np.max(np.abs(m[3] - [0.0, 0.0, 0.0, 1.0])) > ROTATION_TOLERANCE:
    raise DatasetError(f"{where}: pose bottom row must be [0, 0, 0, 1], got {m[3].tolist()}.")
  rot = m[:3, :3]
  ortho_err = np.max(np.abs(rot.T @ rot - np.eye(3)))
  det = np.linalg.det(rot)
  if ortho_err > ROTATION_TOLERANCE or abs(det - 1.0) > ROTATION_TOLERANCE:
    raise DatasetError(f"{where}: pose is not rigid (|R^T R - I| = {ortho_err:.2e}, "
                       f"det R = {det:.4f}); expected a rotation and a translation.")
  m[3] = [0.0, 0.0, 0.0, 1.0]
  return m


def invert_rigid(c2w):
  """[..., 4, 4] camera-to-world -> world-to-camera for rigid transforms (float64)."""
  c2w = np.asarray(c2w, dtype=np.float64)
  rot_t = np.swapaxes(c2w[..., :3, :3], -1, -2)
  out = np.zeros(c2w.shape, np.float64)
  out[..., :3, :3] = rot_t
  out[..., :3, 3] = -np.einsum("...ij,...j->...i", rot_t, c2w[..., :3, 3])
  out[..., 3, 3] = 1.0
  return out
