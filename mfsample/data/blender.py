"""NeRF Synthetic ("Blender") datasets: `transforms_{split}.json` + RGBA PNGs.

Format (Mildenhall et al. 2020), as read here:

* `transforms_{split}.json` holds `camera_angle_x` (horizontal field of view, radians) and
  `frames`, each with `file_path` (relative to the dataset folder, usually without `.png`)
  and `transform_matrix`, a camera-to-world matrix in OpenGL / Blender camera axes (x right,
  y up, looking down -z).
* Optional intrinsics in pixels, top-level or per frame (the instant-ngp extension, written
  by `export_blender`): `fl_x`, `fl_y`, `cx`, `cy`, `w`, `h` (and `camera_angle_y`). They
  override `camera_angle_x`. A `camera_model` and distortion coefficients (nerfstudio) are
  accepted only when a pinhole reproduces them: `mfsample.data.transforms_json` holds the
  rules, shared with other transforms.json readers.
* Every frame's image must be distinct, and so must the view names; `file_path` may be
  absolute (the name is then the absolute path without its suffix).
* Depth, optional, per frame:
  - `depth_file_path`: a float32 `.npy` of metric camera z-depth (0 where nothing was hit),
    written by `export_blender` -> `Views.depths`;
  - `{file_path}_depth_0001.png`: Blender's 8-bit *non-metric* depth (normalised and
    inverted, as in lego's test split) -> `Views.depth_codes`, never `depths`.
"""

from pathlib import Path

import numpy as np

from mfsample.camera import Camera
from mfsample.data import _io, transforms_json
from mfsample.data.views import Views

# OpenGL / Blender camera axes -> OpenCV camera axes (flip y and z).
GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def available_splits(path):
  """Names `s` of the `transforms_{s}.json` files in a dataset folder, sorted."""
  root = Path(path)
  return sorted(p.name[len("transforms_"):-len(".json")]
                for p in root.glob("transforms_*.json"))


def load_blender(path, split, *, downscale=1, background=(1.0, 1.0, 1.0)) -> Views:
  """Loads one split of a NeRF Synthetic dataset.

  Args:
    path: the dataset folder (holding `transforms_{split}.json`).
    split: e.g. "train", "val", "test" (any split with a json file).
    downscale: integer factor; images are box-filtered (premultiplied colour and alpha
      averaged separately, then composited) and intrinsics divided by it.
    background: [3] colour the RGBA images are composited on (3DGS uses white or black).

  Returns:
    `Views` with images [V, H, W, 3] float32 composited on `background`, alphas [V, H, W]
    (None for RGB-only images), cameras in OpenCV axes, metric `depths` when the frames
    carry `depth_file_path`, Blender's non-metric `depth_codes` when `*_depth_0001.png`
    files exist, and names "{file_path without ./ and suffix}" (or the frame's `name`).

  Raises:
    FileNotFoundError: the folder, the json or an image is missing (the message names it).
    DatasetError (a ValueError): unknown split, malformed json, missing keys, images of
      different sizes, non-finite or non-rigid poses.
  """
  root = _io.require_dir(path, "NeRF Synthetic dataset folder")
  downscale = _io.check_downscale(downscale)
  background = _check_background(background)
  if not isinstance(split, str) or not split or "/" in split:
    raise ValueError(f"split must be a non-empty name such as 'train', got {split!r}")
  json_path = root / f"transforms_{split}.json"
  if not json_path.is_file():
    splits = available_splits(root)
    if not splits:
      raise FileNotFoundError(f"{json_path} not found: {root} holds no transforms_*.json, "
                              "is it a NeRF Synthetic dataset?")
    raise _io.DatasetError(f"unknown split {split!r}: {json_path} not found (available "
                           f"splits in {root}: {', '.join(splits)}).")
  meta = _io.read_json(json_path)
  frames = _frames(meta, json_path)

  images, alphas, depths, codes, names, c2ws, intrinsics = [], [], [], [], [], [], []
  size = None
  seen = {}  # image file or view name -> the first frame that has it
  for index, frame in enumerate(frames):
    where = f"{json_path} frame {index}"
    image_path = _image_path(root, frame, where)
    name = _frame_name(frame, root, image_path, where)
    for key, what in ((image_path.resolve(), f"the image {image_path}"),
                      (("name", name), f"the view name {name!r}")):
      if key in seen:
        raise _io.DatasetError(f"{where}: {what} is also that of frame {seen[key]}; every "
                               "frame must be a distinct view.")
      seen[key] = index
    color, alpha = _io.read_image(image_path)
    if size is None:
      size = color.shape[:2]
    elif color.shape[:2] != size:
      raise _io.DatasetError(
          f"{image_path}: image is {color.shape[1]}x{color.shape[0]} but the first frame of "
          f"{json_path} is {size[1]}x{size[0]}; all frames must share one size.")
    depth, code = _read_depth(root, frame, image_path, size, where)
    depths.append(None if depth is None else _downscale_depth(depth, alpha, downscale,
                                                              image_path))
    codes.append(None if code is None else _downscale_depth(code, alpha, downscale,
                                                            image_path))
    color, alpha = _downscale_rgba(color, alpha, downscale, image_path)
    images.append(color)
    alphas.append(alpha)
    names.append(name)
    c2ws.append(_io.validate_rigid(_get(frame, "transform_matrix", where), where,
                                   "'transform_matrix'"))
    fields = transforms_json.FrameFields(meta, frame, where, json_path)
    intrinsics.append(transforms_json.intrinsics(fields, size))

  has_alpha = any(a is not None for a in alphas)
  alpha_arr = None
  if has_alpha:
    alpha_arr = np.stack([np.ones(images[0].shape[:2], np.float32) if a is None else a
                          for a in alphas])
    # Composite premultiplied colour on the background: C = c + (1 - a) bg.
    image_arr = np.stack(images) + (1.0 - alpha_arr[..., None]) * background
  else:
    image_arr = np.stack(images)
  image_arr = np.clip(image_arr, 0.0, 1.0).astype(np.float32)

  cameras = cameras_from_blender(np.stack(c2ws), np.array(intrinsics), size[1], size[0],
                                 downscale)
  return Views(images=image_arr, cameras=cameras, alphas=alpha_arr,
               depths=_stack_optional(depths, json_path, "depth_file_path"),
               names=tuple(names),
               depth_codes=_stack_optional(codes, json_path, "*_depth_0001.png"))


def cameras_from_blender(c2w_gl, intrinsics, width, height, downscale=1):
  """Batched `Camera` from Blender camera-to-world matrices (float64 maths, float32 out).

  Args:
    c2w_gl: [V, 4, 4] camera-to-world, OpenGL axes.
    intrinsics: [V, 4] (fx, fy, cx, cy) in pixels of the full-size image.
    width, height: full-size image size in pixels.
    downscale: integer factor dividing the image size and the intrinsics.
  """
  w2c = _io.invert_rigid(np.asarray(c2w_gl, np.float64) @ GL_TO_CV)
  k = np.asarray(intrinsics, np.float64) / downscale
  return Camera.create(w2c.astype(np.float32), k[:, 0].astype(np.float32),
                       k[:, 1].astype(np.float32), k[:, 2].astype(np.float32),
                       k[:, 3].astype(np.float32), width // downscale, height // downscale)


# ------------------------------------------------------------------ helpers


def _check_background(background):
  bg = np.asarray(background, np.float32)
  if bg.shape != (3,) or not np.all(np.isfinite(bg)):
    raise ValueError(f"background must be 3 finite numbers, got {background!r}")
  return bg


def _frames(meta, json_path):
  if not isinstance(meta, dict):
    raise _io.DatasetError(f"{json_path}: expected a json object at the top level.")
  frames = meta.get("frames")
  if not isinstance(frames, list) or not frames:
    raise _io.DatasetError(f"{json_path}: missing or empty 'frames' list.")
  for index, frame in enumerate(frames):
    if not isinstance(frame, dict):
      raise _io.DatasetError(f"{json_path} frame {index}: expected a json object.")
  return frames


def _get(mapping, key, where):
  if key not in mapping:
    raise _io.DatasetError(f"{where}: missing key {key!r}.")
  return mapping[key]


def _image_path(root, frame, where):
  file_path = _get(frame, "file_path", where)
  if not isinstance(file_path, str) or not file_path:
    raise _io.DatasetError(f"{where}: 'file_path' must be a non-empty string.")
  path = root / file_path
  if path.suffix.lower() not in _io.IMAGE_SUFFIXES:
    path = path.with_name(path.name + ".png")
  return _io.require_file(path, f"image of {where}")


def _frame_name(frame, root, image_path, where):
  """The frame's `name`, else its image path relative to the dataset folder (the absolute
  path for an image outside it) without the suffix."""
  if "name" in frame:
    if not isinstance(frame["name"], str) or not frame["name"]:
      raise _io.DatasetError(f"{where}: 'name' must be a non-empty string, got "
                             f"{frame['name']!r}.")
    return frame["name"]
  try:
    return image_path.relative_to(root).with_suffix("").as_posix()
  except ValueError:  # an absolute file_path elsewhere
    return image_path.with_suffix("").as_posix()


def _downscale_rgba(color, alpha, factor, path):
  """Premultiplies, box-filters, and returns (premultiplied colour, alpha) when alpha exists."""
  if alpha is None:
    return _io.area_downscale(color, factor, path), None
  premult = color * alpha[..., None]
  return (_io.area_downscale(premult, factor, path),
          _io.area_downscale(alpha, factor, path))


def _read_depth(root, frame, image_path, size, where):
  """(metric depth or None, Blender depth code in [0, 1] or None), both [H, W] float32."""
  depth = code = None
  if "depth_file_path" in frame:
    if not isinstance(frame["depth_file_path"], str) or not frame["depth_file_path"]:
      raise _io.DatasetError(f"{where}: 'depth_file_path' must be a non-empty string, got "
                             f"{frame['depth_file_path']!r}.")
    depth_path = _io.require_file(root / frame["depth_file_path"], f"depth of {where}")
    try:
      depth = np.load(depth_path, allow_pickle=False)
    except (ValueError, OSError) as e:
      raise _io.DatasetError(f"{depth_path}: cannot read depth ({e}).") from e
    if depth.shape != size or not np.issubdtype(depth.dtype, np.floating):
      raise _io.DatasetError(f"{depth_path}: expected a float array of shape {size}, got "
                             f"{depth.dtype} {depth.shape}.")
    if not np.all(np.isfinite(depth)) or np.any(depth < 0):
      raise _io.DatasetError(f"{depth_path}: depth must be finite and >= 0.")
    depth = depth.astype(np.float32)
  code_path = image_path.with_name(image_path.stem + "_depth_0001.png")
  if code_path.is_file():
    raw, _ = _io.read_image(code_path)
    if raw.shape[:2] != size:
      raise _io.DatasetError(f"{code_path}: depth image size {raw.shape[:2]} differs from "
                             f"the image {size}.")
    code = raw[..., 0]
  return depth, code


def _downscale_depth(depth, alpha, factor, path):
  """Coverage-weighted mean of the depth of what was hit, per output pixel."""
  if factor == 1:
    return depth
  weight = (depth > 0).astype(np.float32)
  if alpha is not None:
    weight = weight * alpha
  num = _io.area_downscale(weight * depth, factor, path)
  den = _io.area_downscale(weight, factor, path)
  return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0).astype(np.float32)


def _stack_optional(arrays, json_path, what):
  present = [a is not None for a in arrays]
  if not any(present):
    return None
  if not all(present):
    missing = present.index(False)
    raise _io.DatasetError(f"{json_path}: frame {missing} has no depth ({what}) while "
                           "others do; depth must be given for all frames or none.")
  return np.stack(arrays).astype(np.float32)
