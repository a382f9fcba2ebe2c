"""COLMAP reconstructions: a sparse model (binary or text) and its images, read with `pycolmap`.

The layout of COLMAP's output, of Mip-NeRF 360 and of every 3DGS tool:

  scene/
    images/            the photographs (the names the sparse model refers to)
    images_2/ ...      downscaled copies (Mip-NeRF 360 ships 2, 4 and 8; a missing one is
                       made from images/ when read: `mfsample.data.downscaled`)
    sparse/0/          cameras, images, points3D (.bin or .txt; rigs and frames in COLMAP 3.12+)

Conventions, as read here:

* COLMAP's `cam_from_world` maps world points to camera axes x right, y down, z forward: it
  is `Camera.world_to_camera` as it is (OpenCV axes).
* COLMAP puts the centre of the upper-left pixel at (0.5, 0.5), as `mfsample.camera` does, so
  focal lengths and principal points carry over unchanged. Images read from a downscaled
  folder scale them by the ratio of the image size to the calibrated size, per axis (folders
  made by resizing round the size).
* Only pinhole cameras render correctly with a pinhole renderer: PINHOLE and SIMPLE_PINHOLE
  are read; SIMPLE_RADIAL, RADIAL, OPENCV and FULL_OPENCV only when their distortion
  parameters are all exactly zero. Any other camera gets an error naming it: undistort the
  capture first (COLMAP's `image_undistorter`, as 3DGS's `convert.py` does).
* Views are ordered by image name (as 3DGS and nerfstudio order them), and named by the
  image name without its extension; an image listed twice, or two images that would share a
  view name (`a.png`, `a.jpg`), are refused. Images without a pose are not part of the model
  and are skipped. Rotation quaternions must have norm 1 (a zero one is refused, not read as
  the identity).
* The model files are walked before pycolmap reads them (`colmap_files`): a truncated or
  corrupt binary file gives a `DatasetError` naming the file and the record, never a reader
  that exhausts the memory.
* The sparse points come with their colours, for the "SfM points" initialisation of 3DGS.
* Coordinates are returned as stored (no recentring or rescaling; 3DGS uses them as they
  are and derives the scene extent from the cameras).

`export_colmap` writes `Views` (and optionally points) in this layout with pycolmap's own
writer, for other tools and for tests.
"""

from pathlib import Path
from typing import NamedTuple

import numpy as np

from mfsample import arg_checks, fingerprints
from mfsample.camera import Camera
from mfsample.data import _io, colmap_files, downscaled
from mfsample.data.views import Views

# Camera models read as pinholes: {model: number of leading focal / principal point
# parameters}. The ones with distortion parameters are accepted only when those are all 0.
_PINHOLE_MODELS = {"SIMPLE_PINHOLE": 3, "PINHOLE": 4}
_ZERO_DISTORTION_MODELS = {"SIMPLE_RADIAL": 3, "RADIAL": 3, "OPENCV": 4, "FULL_OPENCV": 4}

_UNDISTORT_HINT = ("undistort the capture first, e.g. `colmap image_undistorter --image_path "
                   "scene/input --input_path scene/distorted/sparse/0 --output_path scene "
                   "--output_type COLMAP` (3DGS's convert.py does this), which writes PINHOLE "
                   "cameras and undistorted images")


class PointCloud(NamedTuple):
  """The sparse points of a reconstruction.

  Attributes:
    xyz: [P, 3] float32 world coordinates.
    rgb: [P, 3] float32 colours in [0, 1].
  """

  xyz: np.ndarray
  rgb: np.ndarray

  def __len__(self):
    return len(self.xyz)

  def validate(self, name="points"):
    """Raises ValueError naming `name` unless xyz and rgb are [P, 3], xyz finite and rgb
    floats in [0, 1]; returns the cloud. Colours on another scale are refused, not clipped:
    8-bit (0..255) or 16-bit integers, or floats written in 0..255, would all clip to white."""
    arg_checks.check_real_dtype(f"{name}.xyz", self.xyz)
    arg_checks.check_real_dtype(f"{name}.rgb", self.rgb)
    xyz, rgb = np.asarray(self.xyz, np.float64), np.asarray(self.rgb)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or rgb.shape != xyz.shape:
      raise ValueError(f"{name} must hold xyz [P, 3] and rgb [P, 3], got {list(xyz.shape)} "
                       f"and {list(rgb.shape)}")
    bad = ~np.all(np.isfinite(xyz), axis=-1)
    if np.any(bad):
      raise ValueError(f"{name}.xyz[{int(np.argmax(bad))}] is not finite")
    arg_checks.check_float_dtype(f"{name}.rgb", rgb, "floats in [0, 1] (for 8-bit colours "
                                 "pass rgb / 255, for 16-bit rgb / 65535)")
    outside = np.any(~((rgb >= 0.0) & (rgb <= 1.0)), axis=-1)
    if np.any(outside):
      i = int(np.argmax(outside))
      raise ValueError(f"{name}.rgb[{i}] = {rgb[i].tolist()} is outside [0, 1] "
                       f"({int(outside.sum())} of {len(rgb)} points; colours given in 0..255 "
                       "must be divided by 255)")
    return self

  def box(self, percentile=1.0):
    """(low [3], high [3]) of the points between the `percentile` and 100 - `percentile`
    percentiles per axis: the scene, without the few far-off points (sky, mismatches) that
    a real reconstruction always has."""
    if len(self.xyz) == 0:
      raise ValueError("the point cloud is empty")
    if isinstance(percentile, bool) or not 0.0 <= percentile < 50.0:
      raise ValueError(f"percentile must be a number in [0, 50), got {percentile!r}")
    low = np.percentile(self.xyz, percentile, axis=0)
    high = np.percentile(self.xyz, 100.0 - percentile, axis=0)
    return low.astype(np.float32), high.astype(np.float32)


def _pycolmap():
  try:
    import pycolmap
  except ImportError as err:
    raise ImportError("COLMAP datasets need pycolmap, an optional extra: pip install "
                      "'mfsample[colmap]' (or pip install pycolmap)") from err
  return pycolmap


def find_sparse(root):
  """The sparse model folder of a scene: `sparse/0`, else `sparse`, else the folder itself."""
  root = Path(root)
  for candidate in (root / "sparse" / "0", root / "sparse", root):
    if any((candidate / f"cameras{ext}").is_file() for ext in (".bin", ".txt")):
      return candidate
  raise FileNotFoundError(
      f"no COLMAP sparse model under {root}: expected cameras.bin or cameras.txt (with images "
      f"and points3D) in {root / 'sparse' / '0'}, {root / 'sparse'} or {root}.")


# The files of a sparse model (pycolmap reads rigs and frames where they exist).
_MODEL_FILES = ("cameras", "images", "points3D", "rigs", "frames")


def read_reconstruction(sparse):
  """A `pycolmap.Reconstruction` from a sparse model folder (binary or text).

  Raises:
    FileNotFoundError: the folder or its model files are missing.
    DatasetError: pycolmap cannot parse the files (the message names the folder).
  """
  pycolmap = _pycolmap()
  sparse = _io.require_dir(sparse, "COLMAP sparse model folder")
  for name in ("cameras", "images", "points3D"):
    if not any((sparse / f"{name}{ext}").is_file() for ext in (".bin", ".txt")):
      raise FileNotFoundError(f"{sparse / (name + '.bin')} not found (nor {name}.txt): a "
                              "COLMAP sparse model has cameras, images and points3D files.")
  for file in sorted(sparse.iterdir()):  # the model files pycolmap reads are inputs
    if file.stem in _MODEL_FILES and file.suffix in (".bin", ".txt"):
      fingerprints.note(file)
  # pycolmap trusts the files' counts (a truncated file can exhaust the memory): walk first.
  colmap_files.check_model_files(sparse)
  try:
    return pycolmap.Reconstruction(str(sparse))
  except (ValueError, IndexError, RuntimeError, OSError) as e:
    raise _io.DatasetError(f"{sparse}: cannot read the COLMAP model ({e}).") from e


def load_colmap(path, *, factor=1, sparse=None, background=(1.0, 1.0, 1.0),
                make_downscaled=True):
  """Loads a COLMAP capture: posed images and the sparse points.

  Args:
    path: the scene folder, holding `images/` (or `images_{factor}/`) and the sparse model.
    factor: read the downscaled `images_{factor}/` folder (1: `images/`); intrinsics are
      scaled to the size of the images found there.
    make_downscaled: when `images_{factor}/` is missing, make it from `images/`
      (`mfsample.data.downscaled`: Lanczos, written beside it once, with a log line);
      False: refuse it.
    sparse: the sparse model folder (default: `sparse/0`, else `sparse`, else `path`).
    background: [3] colour that images with an alpha channel are composited on.

  Returns:
    (views, points): `Views` (images [V, H, W, 3] float32 in [0, 1], alphas when the images
    have them, cameras in OpenCV axes, names = image names without extension) ordered by
    image name, and the model's `PointCloud` ordered by point id.

  Raises:
    FileNotFoundError: a missing folder, model file or image (named in the message);
      `downscaled.MissingImageFolder` when `images_{factor}/` is missing and not made.
    DatasetError (a ValueError): a distorted or non-perspective camera (named, with how to
      undistort), unreadable model files, images of different sizes, images whose size is not
      a scaled copy of the camera's, non-finite poses.
  """
  root = _io.require_dir(path, "COLMAP scene folder")
  if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
    raise ValueError(f"factor must be an integer >= 1, got {factor!r}")
  bg = np.asarray(background, np.float32)
  if bg.shape != (3,) or not np.all(np.isfinite(bg)):
    raise ValueError(f"background must be 3 finite numbers, got {background!r}")
  sparse = find_sparse(root) if sparse is None else Path(sparse)
  recon = read_reconstruction(sparse)
  entries = sorted(((im.name, im) for im in recon.images.values() if _has_pose(im)),
                   key=lambda e: e[0])
  if not entries:
    raise _io.DatasetError(f"{sparse}: the model has no posed images.")
  _check_view_names([name for name, _ in entries], sparse)
  intrinsics = {}  # (checked before an images_N/ folder is made for them)
  for name, image in entries:
    if image.camera_id not in intrinsics:
      intrinsics[image.camera_id] = _pinhole(recon.cameras[image.camera_id], sparse, name)
  image_dir = root / "images"
  if factor != 1:
    image_dir = downscaled.image_folder(
        root, factor, lambda: [(_image_file(root / "images", name), name) for name, _ in entries],
        make=make_downscaled)
  elif not image_dir.is_dir():
    found = sorted(p.name for p in root.glob("images*") if p.is_dir())
    raise FileNotFoundError(f"image folder for factor=1 not found: {image_dir} (image "
                            f"folders in {root}: {', '.join(found) or 'none'}).")
  images, alphas, w2cs, ks, names = [], [], [], [], []
  size = None
  for name, image in entries:
    (fx, fy, cx, cy), (cam_w, cam_h) = intrinsics[image.camera_id]
    file = _image_file(image_dir, name)
    color, alpha = _io.read_image(file)
    size = color.shape[:2] if size is None else size
    sx, sy = _io.image_scale(file, color.shape[:2], size, (cam_w, cam_h), entries[0][0],
                             f"camera {image.camera_id} of {sparse}")
    where = f"{sparse} image {name!r}"
    w2c = _io.validate_rigid(_pose_matrix(image, where), where)
    if alpha is not None:
      color = color * alpha[..., None] + (1.0 - alpha[..., None]) * bg
    images.append(color)
    alphas.append(alpha)
    w2cs.append(w2c)
    ks.append((fx * sx, fy * sy, cx * sx, cy * sy))
    names.append(str(Path(name).with_suffix("")))

  alpha_arr = None
  if any(a is not None for a in alphas):
    alpha_arr = np.stack([np.ones(size, np.float32) if a is None else a for a in alphas])
  ks = np.asarray(ks, np.float64)
  cameras = Camera.create(np.stack(w2cs).astype(np.float32), ks[:, 0].astype(np.float32),
                          ks[:, 1].astype(np.float32), ks[:, 2].astype(np.float32),
                          ks[:, 3].astype(np.float32), size[1], size[0])
  views = Views(images=np.clip(np.stack(images), 0.0, 1.0).astype(np.float32), cameras=cameras,
                alphas=alpha_arr, names=tuple(names))
  return views, points_of(recon)


def points_of(recon):
  """The `PointCloud` of a `pycolmap.Reconstruction`, ordered by point id."""
  ids = sorted(recon.points3D)
  xyz = np.array([recon.points3D[i].xyz for i in ids], np.float64).reshape(-1, 3)
  rgb = np.array([recon.points3D[i].color for i in ids], np.float64).reshape(-1, 3)
  bad = ~np.all(np.isfinite(xyz), axis=-1)
  if np.any(bad):
    raise _io.DatasetError(f"the COLMAP model's 3D point {ids[int(np.argmax(bad))]} is not "
                           f"finite ({int(bad.sum())} of {len(ids)} points).")
  return PointCloud(xyz.astype(np.float32), (rgb / 255.0).astype(np.float32))


def _has_pose(image):
  has_pose = getattr(image, "has_pose", True)
  return has_pose() if callable(has_pose) else bool(has_pose)


# COLMAP writes unit quaternions; pycolmap keeps a stored one as it is and normalises it only
# to build the matrix, so a zero quaternion would silently become the identity rotation.
QUATERNION_TOLERANCE = 1e-2


def _pose_matrix(image, where):
  """[3, 4] cam_from_world of a pycolmap image (a method since pycolmap 3.12, a property
  before); DatasetError unless its quaternion is finite with norm 1 (within 1e-2)."""
  pose = image.cam_from_world
  pose = pose() if callable(pose) else pose
  quat = np.asarray(pose.rotation.quat, np.float64)  # (x, y, z, w)
  norm = float(np.linalg.norm(quat))
  if not abs(norm - 1.0) <= QUATERNION_TOLERANCE:
    raise _io.DatasetError(f"{where}: the rotation quaternion (qw, qx, qy, qz) = "
                           f"{quat[[3, 0, 1, 2]].tolist()} has norm {norm:.4g}; COLMAP stores "
                           "unit quaternions (a zero one is no rotation).")
  return np.asarray(pose.matrix(), np.float64)


def _check_view_names(names, sparse):
  """Views are named by the image name without its extension: refuse an image listed twice,
  and two images (`a.png`, `a.jpg`) that would give one view name."""
  stems = {}
  for name in names:
    stem = str(Path(name).with_suffix(""))
    if stem in stems:
      twice = stems[stem] == name
      raise _io.DatasetError(
          f"{sparse}: " + (f"the image {name!r} is listed twice" if twice else
                           f"the images {stems[stem]!r} and {name!r} both give the view name "
                           f"{stem!r}") + "; view names must be unique.")
    stems[stem] = name


def _pinhole(camera, sparse, image_name):
  """((fx, fy, cx, cy), (width, height)) of a pinhole-type camera; DatasetError otherwise."""
  model = str(getattr(camera, "model_name", None) or camera.model.name)
  params = np.asarray(camera.params, np.float64)
  where = f"{sparse}: camera {camera.camera_id} (used by image {image_name!r})"
  lead = _PINHOLE_MODELS.get(model, _ZERO_DISTORTION_MODELS.get(model))
  if lead is None:
    raise _io.DatasetError(f"{where} has the camera model {model}, which the pinhole renderer "
                           f"cannot reproduce; {_UNDISTORT_HINT}.")
  if model in _ZERO_DISTORTION_MODELS and np.any(params[lead:] != 0.0):
    raise _io.DatasetError(
        f"{where} has the distorted camera model {model} (distortion parameters "
        f"{params[lead:].tolist()}); {_UNDISTORT_HINT}.")
  if lead == 3:  # a single focal length
    f, cx, cy = params[:3]
    fx = fy = f
  else:
    fx, fy, cx, cy = params[:4]
  values = np.array([fx, fy, cx, cy])
  if not np.all(np.isfinite(values)) or fx <= 0 or fy <= 0:
    raise _io.DatasetError(f"{where}: invalid intrinsics fx={fx}, fy={fy}, cx={cx}, cy={cy}.")
  size = int(camera.width), int(camera.height)
  if not all(1 <= v < 2 ** 31 for v in size):  # a negative text value wraps to 2^64 - v
    raise _io.DatasetError(f"{where}: invalid image size width={size[0]}, height={size[1]} "
                           "(must be >= 1).")
  return (float(fx), float(fy), float(cx), float(cy)), size


def _image_file(image_dir, name):
  """The file of image `name` in `image_dir`: the name itself, else the same stem with another
  image extension (downscaled folders are often written as PNG)."""
  path = image_dir / name
  if path.is_file():
    return path
  stem = path.with_suffix("")
  for candidate in sorted(stem.parent.glob(stem.name + ".*")) if stem.parent.is_dir() else []:
    if candidate.suffix.lower() in _io.IMAGE_SUFFIXES:
      return candidate
  raise FileNotFoundError(f"image of the COLMAP model not found: {path} (nor "
                          f"{stem.name} with another image extension).")


# ------------------------------------------------------------------------- export


def export_colmap(path, views: Views, points: PointCloud | None = None, *, binary=True,
                  overwrite=False):
  """Writes `views` (and `points`) as a COLMAP capture that `load_colmap` and 3DGS tools read.

  Writes `path/images/{index:05d}_{name}.png` (8-bit RGB; the index keeps the view order
  when sorted by name) and `path/sparse/0/` with pycolmap's writer: one PINHOLE camera per
  distinct set of intrinsics, one posed image per view, and the points with their colours
  (no tracks). `load_colmap(path)` returns the same cameras (float32 round trip), the images
  quantised to 8 bits, and the points.

  Args:
    path: output folder (created if needed).
    views: the views to write.
    points: optional `PointCloud`.
    binary: write .bin files (COLMAP's default) instead of .txt.
    overwrite: replace an existing sparse model (otherwise FileExistsError).

  Returns:
    the sparse model folder.
  """
  import imageio.v3 as iio

  pycolmap = _pycolmap()
  root = Path(path)
  sparse = root / "sparse" / "0"
  if any(sparse.glob("cameras.*")) and not overwrite:
    raise FileExistsError(f"{sparse} holds a model; pass overwrite=True to replace it.")
  views.validate()
  if points is not None:
    PointCloud(*points).validate()
  images = np.asarray(views.images, np.float32)
  cameras = views.cameras
  (root / "images").mkdir(parents=True, exist_ok=True)
  sparse.mkdir(parents=True, exist_ok=True)
  recon = pycolmap.Reconstruction()
  w2c = np.asarray(cameras.world_to_camera, np.float64)
  ks = np.stack([np.asarray(getattr(cameras, k), np.float64) for k in ("fx", "fy", "cx", "cy")],
                axis=-1)
  camera_ids = {}
  for i in range(len(images)):
    key = tuple(ks[i].tolist())
    if key not in camera_ids:
      camera_ids[key] = len(camera_ids) + 1
      recon.add_camera_with_trivial_rig(pycolmap.Camera(
          camera_id=camera_ids[key], model="PINHOLE", width=int(cameras.width),
          height=int(cameras.height), params=list(key)))
    stem = f"{i:05d}"
    if views.names:
      stem += "_" + "".join(c if c.isalnum() or c in "-_." else "_" for c in str(views.names[i]))
    name = f"{stem}.png"
    iio.imwrite(root / "images" / name,
                np.round(np.clip(images[i], 0.0, 1.0) * 255.0).astype(np.uint8))
    image = pycolmap.Image(name=name, camera_id=camera_ids[key], image_id=i + 1)
    pose = pycolmap.Rigid3d(pycolmap.Rotation3d(w2c[i, :3, :3]), w2c[i, :3, 3])
    recon.add_image_with_trivial_frame(image, pose)
  if points is not None:
    rgb = np.round(np.asarray(points.rgb, np.float64) * 255.0)
    for xyz, color in zip(np.asarray(points.xyz, np.float64), rgb.astype(np.uint8),
                          strict=True):
      recon.add_point3D(xyz, pycolmap.Track(), color)
  for old in sparse.iterdir():
    if old.suffix in (".bin", ".txt"):
      old.unlink()
  (recon.write_binary if binary else recon.write_text)(str(sparse))
  return sparse
