"""Writes `Views` as a NeRF Synthetic dataset that `load_blender` (and other tools) can read."""

import math
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from mfsample._json import atomic_path, write_json
from mfsample.data import _io
from mfsample.data.blender import GL_TO_CV
from mfsample.data.views import Views


def export_blender(path, views: Views, *, split="train", background=(1.0, 1.0, 1.0),
                   overwrite=False):
  """Writes one split: `transforms_{split}.json`, `{split}/r_{i}.png`, `{split}/r_{i}_depth.npy`.

  Images are stored as 8-bit RGBA PNGs with straight (un-premultiplied) colour, recovered from
  the composited images with `background`; without alphas, as RGB PNGs. The json has the
  standard `camera_angle_x` and `transform_matrix` (camera-to-world, OpenGL axes) plus the
  exact per-frame intrinsics `fl_x, fl_y, cx, cy` (pixels), the image size `w, h`, each
  view's `name`, and `depth_file_path` to a float32 `.npy` of metric z-depth when
  `views.depths` is set. `load_blender(path, split, background=background)` reads it back:
  exactly for images that are already 8-bit quantised, within 1/255 otherwise.

  Args:
    path: output folder (created if needed).
    views: the views to write.
    split: split name, e.g. "train" or "test".
    background: [3] colour the images were composited on.
    overwrite: replace an existing `transforms_{split}.json` (otherwise FileExistsError).

  Returns:
    The path of the written json file.
  """
  if not isinstance(split, str) or not split or "/" in split:
    raise ValueError(f"split must be a non-empty name such as 'train', got {split!r}")
  root = Path(path)
  json_path = root / f"transforms_{split}.json"
  if json_path.exists() and not overwrite:
    raise FileExistsError(f"{json_path} exists; pass overwrite=True to replace it.")
  views.validate()
  cameras = views.cameras
  images = np.asarray(views.images, np.float32)
  num, height, width = images.shape[:3]
  bg = np.asarray(background, np.float32)
  if bg.shape != (3,) or not np.all(np.isfinite(bg)):
    raise ValueError(f"background must be 3 finite numbers, got {background!r}")
  (root / split).mkdir(parents=True, exist_ok=True)

  w2c = np.asarray(cameras.world_to_camera, np.float64)
  c2w_gl = _io.invert_rigid(w2c) @ GL_TO_CV  # GL_TO_CV is its own inverse
  fx, fy, cx, cy = (np.asarray(getattr(cameras, k), np.float64) for k in ("fx", "fy", "cx",
                                                                        "cy"))
  names = views.names if views.names else tuple(f"{split}/r_{i}" for i in range(num))
  frames = []
  for i in range(num):
    stem = f"r_{i}"
    _write_png(root / split / f"{stem}.png", images[i],
               None if views.alphas is None else np.asarray(views.alphas[i], np.float32), bg)
    frame = {
        "file_path": f"./{split}/{stem}",
        "name": str(names[i]),
        "transform_matrix": c2w_gl[i].tolist(),
        "fl_x": float(fx[i]), "fl_y": float(fy[i]), "cx": float(cx[i]), "cy": float(cy[i]),
    }
    if views.depths is not None:
      with atomic_path(root / split / f"{stem}_depth.npy") as tmp:
        np.save(tmp, np.asarray(views.depths[i], np.float32))
      frame["depth_file_path"] = f"./{split}/{stem}_depth.npy"
    frames.append(frame)
  meta = {
      "camera_angle_x": 2.0 * math.atan(0.5 * width / float(fx[0])),
      "w": width,
      "h": height,
      "depth_unit": "metres of camera z-depth (0 = nothing hit)",
      "frames": frames,
  }
  # The json last (every file is written atomically): it is what marks a split complete.
  write_json(json_path, meta)
  return json_path


def _write_png(path, image, alpha, background):
  if alpha is None:
    with atomic_path(path) as tmp:
      iio.imwrite(tmp, _to_u8(image))
    return
  alpha_q = _to_u8(alpha)
  a = alpha_q.astype(np.float32) / 255.0
  # Un-composite: C = a c + (1 - a) bg  =>  c = (C - (1 - a) bg) / a, using the quantised a
  # so that re-compositing the stored values lands closest to C.
  premult = image - (1.0 - a[..., None]) * background
  straight = np.where(a[..., None] > 0, premult / np.maximum(a[..., None], 1e-12), 0.0)
  with atomic_path(path) as tmp:
    iio.imwrite(tmp, np.concatenate([_to_u8(straight), alpha_q[..., None]], axis=-1))


def _to_u8(x):
  return np.round(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)
