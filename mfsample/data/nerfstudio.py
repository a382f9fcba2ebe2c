"""nerfstudio captures: the `transforms.json` layout of `ns-process-data`, read and written.

The layout (`ns-process-data images --data photos/ --output-dir scene/`):

  scene/
    transforms.json    cameras and frames (below)
    images/            the photographs (frame_00001.png ...)
    images_2/ ...      downscaled copies with the same file names (a missing one is made
                       from the frames' images when read: `mfsample.data.downscaled`)
    sparse_pc.ply      the SfM points (`ply_file_path`), in the frames' world
    colmap/            COLMAP's own model (read it with `load_colmap` if you prefer)

`transforms.json` holds the intrinsics `fl_x, fl_y, cx, cy, w, h` (pixels), `camera_model`
and distortion `k1 k2 k3 k4 p1 p2` at the top level when every frame shares them, or in each
frame otherwise; a list of `frames`, each with `file_path` and `transform_matrix`; optionally
`applied_transform` and `ply_file_path`. Conventions, as nerfstudio's own dataparser reads
them (`nerfstudio/data/dataparsers/nerfstudio_dataparser.py`):

* `transform_matrix` is camera-to-world with OpenGL camera axes (x right, y up, z backward):
  `Camera.world_to_camera` = inverse(transform_matrix @ diag(1, -1, -1, 1)).
* Pixel centres sit at +0.5 in nerfstudio as in COLMAP and mfsample, so `fl_x, fl_y, cx, cy`
  carry over unchanged.
* A key at the top level applies to every frame; a frame carries its own value only where the
  top level has none. A frame whose value contradicts the top level's is refused (nerfstudio
  would silently use the top level's).
* `applied_transform` (3 x 4) is what `ns-process-data` applied to the reconstruction it read:
  it maps the original world (COLMAP's) to the world of `transform_matrix` and of the points
  in `ply_file_path` (ns-process-data transforms them too). `frame="transforms"` (default)
  returns cameras and points in the world of the file; `frame="original"` undoes
  `applied_transform`, giving the coordinates of the reconstruction it came from: the cameras
  of `load_colmap(scene/colmap)` and of a 3DGS model trained on that COLMAP model.
* Frames are ordered by file path (as nerfstudio orders them) and named by the file's path
  relative to the capture folder without its extension, less the leading `images/` when
  every frame lies in that folder (`images/cam0/0001.png` -> `cam0/0001`). Two frames of one
  image file (a frame listed twice, `images/a.png` and `./images/a.png`) or of one name
  (`a.png` and `a.jpg`) are refused, naming both frames.
* `images_{N}/` holds the same files: `images/cam0/0001.png` is read from
  `images_N/cam0/0001.png` (a frame outside `images/` from `images_N/` + its file name,
  nerfstudio's rule; two frames reaching one file are refused). The intrinsics are scaled to
  the size of the images found there (as `load_colmap` does).
* Only pinhole cameras render correctly with a pinhole renderer: `PINHOLE`,
  `SIMPLE_PINHOLE`, and `OPENCV`, `SIMPLE_RADIAL`, `RADIAL`, `FULL_OPENCV` (or no
  `camera_model`, nerfstudio's perspective default) whose distortion (`k1`..`k6`, `p1`, `p2`,
  `distortion_params`) is all zero, at the top level and in every frame. Anything else (a
  fisheye, an equirectangular camera, non-zero distortion) is refused naming the model and the
  frame: process the capture with `ns-process-data ... --camera-type pinhole`, which has
  COLMAP solve for distortion-free cameras.
* Intrinsics no photograph has are refused naming the frame and the key
  (`transforms_json.check_pinhole`): focal lengths <= 0, under 0.05 or over 1000 times the
  image size (values normalised by the image size, say), a principal point outside the image.
* `mask_path` is refused: the training loss has no per-pixel mask, so the masked pixels would
  be fitted as they are. `depth_file_path` is not read (nothing here uses depth).
* nerfstudio's trainers then re-centre, orient and scale the cameras for their own use
  (`dataparser_transforms.json` in their output folder); that is not part of the capture, and a
  model exported by `ns-export gaussian-splat` lives in that frame, not in this one.

`export_nerfstudio` writes `Views` (and points) in this layout, for nerfstudio and for tests.
"""

import os
from pathlib import Path

import numpy as np

from mfsample.camera import Camera
from mfsample.data import _io, downscaled, transforms_json
from mfsample.data.colmap import PointCloud
from mfsample.data.views import Views

GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenGL camera axes <-> OpenCV (its own inverse)

# The per-camera keys of transforms.json (top level or per frame).
_INTRINSICS = ("fl_x", "fl_y", "cx", "cy")
_SIZE = ("w", "h")
_DISTORTION = ("k1", "k2", "k3", "k4", "k5", "k6", "p1", "p2")
# Perspective models: read when their distortion is zero. Missing camera_model: perspective.
_PERSPECTIVE = ("PINHOLE", "SIMPLE_PINHOLE", "OPENCV", "SIMPLE_RADIAL", "RADIAL", "FULL_OPENCV")
_HINT = ("process the capture with `ns-process-data images ... --camera-type pinhole` (COLMAP "
         "then solves distortion-free cameras), or undistort the images and write PINHOLE "
         "intrinsics")

# ns-process-data's applied_transform (COLMAP's world -> nerfstudio's: y and z swapped, the new
# z negated): what `export_nerfstudio(..., applied_transform=NS_PROCESS_DATA_TRANSFORM)` records.
NS_PROCESS_DATA_TRANSFORM = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
                                      [0.0, -1.0, 0.0, 0.0]])


def load_nerfstudio(path, *, factor=1, frame="transforms", background=(1.0, 1.0, 1.0),
                    make_downscaled=True):
  """Loads a nerfstudio capture: posed images and the SfM points.

  Args:
    path: the scene folder holding `transforms.json`, or the json file itself.
    factor: read the downscaled `images_{factor}/` copies (1: the frames' own files).
    make_downscaled: when `images_{factor}/` is missing, make it from the frames' own files
      (`mfsample.data.downscaled`: Lanczos, written beside them once, with a log line);
      False: refuse it.
    frame: "transforms" (the world of transform_matrix) or "original" (`applied_transform`
      undone; the module docstring says which is which).
    background: [3] colour that images with an alpha channel are composited on.

  Returns:
    (views, points): `Views` (images [V, H, W, 3] float32 in [0, 1], alphas when the images
    have them, cameras in OpenCV axes, names) ordered by file path, and the `PointCloud` of
    `ply_file_path` (empty when the capture names none).

  Raises:
    FileNotFoundError: a missing folder, json, image or point file (named in the message).
    DatasetError (a ValueError): malformed json, a missing, malformed or contradictory key
      (named with its frame), a distorted or non-perspective camera, implausible intrinsics,
      `mask_path`, a non-rigid pose, two frames of one image or one name, images of different
      sizes or not a scaled copy of their frame's `w` x `h`, float images with values that are
      not finite or outside [0, 1].
  """
  path = Path(path)
  json_path = path if path.suffix == ".json" else path / "transforms.json"
  if not path.exists():
    raise FileNotFoundError(f"nerfstudio capture not found: {path}")
  root = json_path.parent
  if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
    raise ValueError(f"factor must be an integer >= 1, got {factor!r}")
  if frame not in ("transforms", "original"):
    raise ValueError(f"frame must be 'transforms' or 'original', got {frame!r}")
  bg = np.asarray(background, np.float64)
  if bg.shape != (3,) or not np.all(np.isfinite(bg)):
    raise ValueError(f"background must be 3 finite numbers, got {background!r}")
  meta = _io.read_json(json_path)
  if not isinstance(meta, dict) or not isinstance(meta.get("frames"), list):
    raise _io.DatasetError(f"{json_path}: expected an object with a 'frames' list.")
  if not meta["frames"]:
    raise _io.DatasetError(f"{json_path}: 'frames' is empty.")
  applied = applied_transform(meta, json_path)
  to_original = np.linalg.inv(applied) if frame == "original" else np.eye(4)

  order = []  # (file path, index in the json) of every frame
  for i, entry in enumerate(meta["frames"]):
    if not isinstance(entry, dict) or not isinstance(entry.get("file_path"), str) or not (
        entry["file_path"]):
      raise _io.DatasetError(f"{json_path}: frames[{i}] needs a non-empty 'file_path' string.")
    order.append((str(Path(entry["file_path"])), i))
  order.sort()
  frames = [meta["frames"][i] for _, i in order]
  names = _frame_names(root, [f["file_path"] for f in frames])
  wheres = [f"{json_path}: frame {entry['file_path']!r}" for entry in frames]
  # (every camera checked before an images_N/ folder is made for it)
  pinholes = [_pinhole(meta, entry, where) for entry, where in zip(frames, wheres, strict=True)]
  if factor > 1:
    downscaled.image_folder(root, factor, lambda: [
        (_frame_image(root, f["file_path"], 1), Path(f["file_path"]).name) for f in frames],
        make=make_downscaled, source_folder=None)
  images, alphas, w2cs, ks = [], [], [], []
  size = None
  seen = {}  # image file or view name -> (index in the json, file_path) of its first frame
  for (_, index), entry, name, where, pinhole in zip(order, frames, names, wheres, pinholes,
                                                     strict=True):
    (fx, fy, cx, cy), (cam_w, cam_h) = pinhole
    file = _frame_image(root, entry["file_path"], factor)
    for key, what in (((root / entry["file_path"]).resolve(), "the image"),
                      (file.resolve(), "the image"), (("name", name), "the view name")):
      shown = repr(name) if what == "the view name" else key
      if key in seen and seen[key][0] != index:
        raise _io.DatasetError(
            f"{json_path}: frames[{seen[key][0]}] ({seen[key][1]!r}) and frames[{index}] "
            f"({entry['file_path']!r}) have {what} {shown}; every frame must be a distinct "
            "view (a frame listed twice would be both trained on and held out).")
      seen[key] = (index, entry["file_path"])
    color, alpha = _io.read_image(file)
    size = color.shape[:2] if size is None else size
    sx, sy = _io.image_scale(file, color.shape[:2], size, (cam_w, cam_h), "the first frame's",
                             where)
    if "transform_matrix" not in entry:
      raise _io.DatasetError(f"{where} has no 'transform_matrix'.")
    c2w = _io.validate_rigid(entry["transform_matrix"], where, "'transform_matrix'")
    # The true inverse (not a transpose): a float32 pose written by export_nerfstudio reads
    # back bit for bit.
    w2cs.append(np.linalg.inv(to_original @ c2w @ GL_TO_CV))
    if alpha is not None:
      color = color * alpha[..., None] + (1.0 - alpha[..., None]) * bg
    images.append(color)
    alphas.append(alpha)
    ks.append((fx * sx, fy * sy, cx * sx, cy * sy))

  alpha_arr = None
  if any(a is not None for a in alphas):
    alpha_arr = np.stack([np.ones(size, np.float32) if a is None else a for a in alphas])
  ks = np.asarray(ks, np.float64).astype(np.float32)
  cameras = Camera.create(np.stack(w2cs).astype(np.float32), ks[:, 0], ks[:, 1], ks[:, 2],
                          ks[:, 3], size[1], size[0])
  views = Views(images=np.clip(np.stack(images), 0.0, 1.0).astype(np.float32), cameras=cameras,
                alphas=alpha_arr, names=tuple(names))
  points = PointCloud(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32))
  if meta.get("ply_file_path") is not None:
    if not isinstance(meta["ply_file_path"], str) or not meta["ply_file_path"]:
      raise _io.DatasetError(f"{json_path}: 'ply_file_path' must be a non-empty string, got "
                             f"{_io.short(meta['ply_file_path'])}.")
    points = read_points(root / meta["ply_file_path"])
    if frame == "original":
      xyz = np.asarray(points.xyz, np.float64) @ to_original[:3, :3].T + to_original[:3, 3]
      points = PointCloud(xyz.astype(np.float32), points.rgb)
  return views, points


def applied_transform(meta, where="transforms.json"):
  """[4, 4] float64 `applied_transform` of a transforms.json dict (identity without one)."""
  if "applied_transform" not in meta:
    return np.eye(4)
  return _io.validate_rigid(meta["applied_transform"], where, "'applied_transform'")


def _raw(meta, entry, key, where):
  """A per-camera key as stored: the top level's, else the frame's (None when neither has it);
  refused when both have it and they disagree."""
  top, own = meta.get(key), entry.get(key)
  if top is not None and own is not None and top != own:
    raise _io.DatasetError(f"{where} has {key} = {own!r} but the top level says {top!r}; "
                           "nerfstudio uses the top level's: keep one of them.")
  return top if top is not None else own


def _value(meta, entry, key, where, default=None):
  """A per-camera number: the top level's, else the frame's; refused when they disagree."""
  if _raw(meta, entry, key, where) is None:
    if default is not None:
      return default
    raise _io.DatasetError(f"{where}: '{key}' is neither in the frame nor at the top level.")
  return _io.number(meta if meta.get(key) is not None else entry, key, where,
                    integer=key in _SIZE)


def _pinhole(meta, entry, where):
  """((fx, fy, cx, cy), (w, h)) of a frame's camera; DatasetError for a distorted or
  non-perspective one (top-level or per-frame keys alike), implausible intrinsics or masks."""
  for model in (meta.get("camera_model"), entry.get("camera_model")):
    if model is not None and not isinstance(model, str):
      raise _io.DatasetError(f"{where}: 'camera_model' must be a string, got "
                             f"{_io.short(model)}.")
    if model is not None and model not in _PERSPECTIVE:
      raise _io.DatasetError(f"{where} has the camera model {model!r}, which the pinhole "
                             f"renderer cannot reproduce; {_HINT}.")
  model = _raw(meta, entry, "camera_model", where) or "OPENCV"
  distortion = {k: _value(meta, entry, k, where, default=0.0) for k in _DISTORTION}
  for scope, mapping in (("", entry), (" (top level)", meta)):
    listed = transforms_json.distortion_list(mapping.get("distortion_params"), where + scope)
    if any(listed):
      distortion["distortion_params" + scope] = listed
  bad = {k: v for k, v in distortion.items() if np.any(np.asarray(v) != 0)}
  if bad:
    raise _io.DatasetError(f"{where} has the camera model {model!r} with distortion {bad}; "
                           f"{_HINT}.")
  transforms_json.refuse_masks(entry, where)
  transforms_json.refuse_masks(meta, f"{where} (top level)")
  fx, fy, cx, cy = (_value(meta, entry, k, where) for k in _INTRINSICS)
  w, h = (_value(meta, entry, k, where) for k in _SIZE)
  if w < 1 or h < 1:
    raise _io.DatasetError(f"{where}: the image size w={w}, h={h} must be at least 1 pixel.")
  transforms_json.check_pinhole(where, w, h, fx, fy, cx, cy)
  return (fx, fy, cx, cy), (w, h)


def _relative_parts(root, file_path):
  """The parts of a frame's `file_path` under the capture folder, normalised (`./`, `a/../`
  removed); an absolute path outside the folder stays absolute."""
  path = Path(os.path.normpath(root / file_path))
  try:
    return path.relative_to(Path(os.path.normpath(root))).parts
  except ValueError:
    return path.parts


def _frame_image(root, file_path, factor):
  """The image file of a frame: `file_path` under the capture, or for factor N its copy in
  `images_N/`: the path under `images/` kept (`images/cam0/1.png` -> `images_N/cam0/1.png`),
  the file name alone for a frame outside `images/` (nerfstudio's rule); with another image
  extension if need be."""
  file = root / file_path
  if factor > 1:
    folder = root / f"images_{int(factor)}"
    if not folder.is_dir():
      found = sorted(p.name for p in root.glob("images*") if p.is_dir())
      raise FileNotFoundError(f"image folder for factor={factor} not found: {folder} (image "
                              f"folders in {root}: {', '.join(found) or 'none'}).")
    parts = _relative_parts(root, file_path)
    file = folder.joinpath(*(parts[1:] if len(parts) > 1 and parts[0] == "images"
                             else parts[-1:]))
  if file.is_file():
    return file
  # Downscaled copies are often written as PNG whatever the originals are.
  for candidate in sorted(file.parent.glob(file.stem + ".*")) if file.parent.is_dir() else []:
    if candidate.suffix.lower() in _io.IMAGE_SUFFIXES:
      return candidate
  raise FileNotFoundError(f"image of frame {file_path!r} not found: {file} (nor {file.stem} "
                          "with another image extension).")


def _frame_names(root, file_paths):
  """The view names of frames: each `file_path` relative to the capture without its extension,
  less the leading `images/` when every frame lies in that folder (COLMAP's image names)."""
  parts = [list(_relative_parts(root, f)) for f in file_paths]
  if all(len(p) > 1 and p[0] == "images" for p in parts):
    parts = [p[1:] for p in parts]
  return [Path(*p).with_suffix("").as_posix() for p in parts]


def read_points(path):
  """The `PointCloud` of a point-cloud .ply (ASCII, as ns-process-data writes it, or binary):
  float x, y, z and optional red, green, blue (grey without), read in full (`ply.read_ply_data`).
  Integer colours are scaled by their type's range (uchar 0..255, ushort 0..65535); float
  colours must lie in [0, 1] (floats in 0..255 are refused, naming the property, not clipped
  to white)."""
  from mfsample.data.ply import read_ply_data

  path = _io.require_file(path, "point cloud (ply_file_path)")
  try:
    data = read_ply_data(path, allow_ascii=True, what="point cloud (ply_file_path)")
  except _io.DatasetError:
    raise
  except Exception as e:  # plyfile raises its own types for malformed files
    raise _io.DatasetError(f"{path}: cannot be read as a PLY file ({e}).") from e
  if "vertex" not in [e.name for e in data.elements]:
    raise _io.DatasetError(f"{path}: no 'vertex' element.")
  vertex = data["vertex"].data
  names = vertex.dtype.names or ()
  missing = [c for c in "xyz" if c not in names]
  if missing:
    raise _io.DatasetError(f"{path}: missing vertex propert{'ies' if len(missing) > 1 else 'y'} "
                           f"{', '.join(missing)}.")
  xyz = np.stack([np.asarray(vertex[c], np.float64) for c in "xyz"], axis=-1)
  if not np.all(np.isfinite(xyz)):
    raise _io.DatasetError(f"{path}: non-finite point coordinates.")
  if all(c in names for c in ("red", "green", "blue")):
    rgb = np.stack([_colour(vertex[c], c, path) for c in ("red", "green", "blue")], -1)
  else:
    rgb = np.full_like(xyz, 0.5)
  return PointCloud(xyz.astype(np.float32), rgb.astype(np.float32))


def _colour(values, name, path):
  """[P] float64 in [0, 1] of one colour property; DatasetError naming it otherwise."""
  dtype = values.dtype
  if np.issubdtype(dtype, np.integer):
    if np.any(values < 0):
      raise _io.DatasetError(f"{path}: vertex property {name} holds negative colours "
                             f"(type {dtype}).")
    return np.asarray(values, np.float64) / float(np.iinfo(dtype).max)
  values = np.asarray(values, np.float64)
  outside = ~((values >= 0.0) & (values <= 1.0))
  if np.any(outside):
    i = int(np.argmax(outside))
    raise _io.DatasetError(f"{path}: vertex property {name} = {values[i]:g} in row {i} is "
                           f"outside [0, 1] ({int(outside.sum())} rows): float colours are in "
                           "[0, 1] (8-bit colours are stored as uchar).")
  return values


# ------------------------------------------------------------------------- writing


def frames_of(cameras: Camera, names, *, applied=None, image_dir="images", image_suffix=".png",
              per_frame_intrinsics=None):
  """(top-level intrinsics dict, frames list) of transforms.json for a batch of cameras.

  Args:
    cameras: `Camera` batched over [V].
    names: V file stems (without folder and extension).
    applied: optional [3, 4] or [4, 4] `applied_transform` to write the poses through.
    image_dir, image_suffix: where the frames' `file_path` points.
    per_frame_intrinsics: write intrinsics in every frame (default: only when they differ).
  """
  w2c = np.asarray(cameras.world_to_camera, np.float64).reshape(-1, 4, 4)
  applied = np.eye(4) if applied is None else _as_4x4(applied)
  ks = np.stack([np.asarray(getattr(cameras, k), np.float32).reshape(-1).astype(np.float64)
                 for k in ("fx", "fy", "cx", "cy")], axis=-1)
  if per_frame_intrinsics is None:
    per_frame_intrinsics = bool(np.any(ks != ks[:1]))
  size = {"w": int(cameras.width), "h": int(cameras.height)}
  top = {"camera_model": "PINHOLE"}
  if not per_frame_intrinsics:
    top.update(dict(zip(_INTRINSICS, ks[0].tolist(), strict=True)), **size)
  frames = []
  for i in range(len(w2c)):
    c2w = applied @ np.linalg.inv(w2c[i]) @ GL_TO_CV
    frame = {"file_path": f"{image_dir}/{names[i]}{image_suffix}",
             "transform_matrix": c2w.tolist()}
    if per_frame_intrinsics:
      frame.update(dict(zip(_INTRINSICS, ks[i].tolist(), strict=True)), **size)
    frames.append(frame)
  return top, frames


def _as_4x4(matrix):
  m = np.asarray(matrix, np.float64)
  return np.concatenate([m, [[0.0, 0.0, 0.0, 1.0]]]) if m.shape == (3, 4) else m


def export_nerfstudio(path, views: Views, points: PointCloud | None = None, *,
                      applied_transform=None, downscales=(), overwrite=False):
  """Writes `views` (and `points`) as a nerfstudio capture that `load_nerfstudio` and
  nerfstudio's dataparser read.

  Writes `path/images/{index:05d}_{name}.png` (8-bit RGB; the index keeps the view order),
  `images_{N}/` copies box-filtered by each factor N of `downscales` (the image size must be
  divisible by N), `sparse_pc.ply` (binary float32 x, y, z and 8-bit colours) when `points`
  are given, and `transforms.json` last: PINHOLE intrinsics at the top level when the views
  share them (per frame otherwise) and camera-to-world `transform_matrix` in OpenGL axes.

  Args:
    path: output folder (created if needed).
    views: the views to write.
    points: optional `PointCloud`.
    applied_transform: optional [3, 4] rigid transform from the views' world to the written
      one, recorded as `applied_transform` (e.g. `NS_PROCESS_DATA_TRANSFORM`, what
      ns-process-data applies to a COLMAP model); the points are transformed too.
    downscales: integer factors of the `images_N/` copies to write.
    overwrite: replace an existing transforms.json (otherwise FileExistsError).

  Returns:
    the path of transforms.json. `load_nerfstudio(path)` returns the views' cameras (and
    `frame="original"` the untransformed ones), the images quantised to 8 bits, the points.
  """
  import imageio.v3 as iio

  from mfsample._json import atomic_path, write_json
  from mfsample.data.ply import _plyfile

  root = Path(path)
  json_path = root / "transforms.json"
  if json_path.exists() and not overwrite:
    raise FileExistsError(f"{json_path} exists; pass overwrite=True to replace it.")
  images = np.asarray(views.images, np.float32)
  cameras = views.cameras
  if images.ndim != 4 or images.shape[-1] != 3 or cameras.batch_shape != (len(images),):
    raise ValueError(f"views must hold [V, H, W, 3] images and V cameras, got images "
                     f"{images.shape} and cameras {cameras.batch_shape}")
  applied = None
  if applied_transform is not None:
    applied = _io.validate_rigid(applied_transform, "applied_transform", "applied_transform")
  if points is not None:  # before anything is written; colours are refused, not clipped
    PointCloud(*points).validate()
  stems = []
  for i in range(len(images)):
    stem = f"{i:05d}"
    if views.names:
      stem += "_" + "".join(c if c.isalnum() or c in "-_." else "_" for c in str(views.names[i]))
    stems.append(stem)
  for factor in (1, *(int(f) for f in downscales)):
    folder = root / ("images" if factor == 1 else f"images_{factor}")
    folder.mkdir(parents=True, exist_ok=True)
    for stem, image in zip(stems, images, strict=True):
      small = _io.area_downscale(np.clip(image, 0.0, 1.0), factor)
      with atomic_path(folder / f"{stem}.png") as tmp:
        iio.imwrite(tmp, np.round(small * 255.0).astype(np.uint8))
  top, frames = frames_of(cameras, stems, applied=applied)
  meta = dict(top)
  if applied is not None:
    meta["applied_transform"] = applied[:3].tolist()
  if points is not None:
    xyz = np.asarray(points.xyz, np.float64)
    if applied is not None:
      xyz = xyz @ applied[:3, :3].T + applied[:3, 3]
    table = np.empty(len(xyz), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                      ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    for j, c in enumerate("xyz"):
      table[c] = xyz[:, j]
    rgb = np.round(np.asarray(points.rgb, np.float64) * 255.0)
    for j, c in enumerate(("red", "green", "blue")):
      table[c] = rgb[:, j]
    plyfile = _plyfile()
    with atomic_path(root / "sparse_pc.ply") as tmp:
      plyfile.PlyData([plyfile.PlyElement.describe(table, "vertex")]).write(tmp)
    meta["ply_file_path"] = "sparse_pc.ply"
  meta["frames"] = frames
  write_json(json_path, meta)  # last: a complete capture has its json
  return json_path
