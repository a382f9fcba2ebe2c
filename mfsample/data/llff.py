"""Forward-facing LLFF captures: `poses_bounds.npy` + `images_{factor}/` (Mildenhall et al. 2019).

`poses_bounds.npy` is a float array [V, 17]. Row v holds a 3x5 matrix, row-major, then the
near and far depth bounds of view v:

    [ r00 r01 r02 t0 h ]
    [ r10 r11 r12 t1 w ]      columns 0-2: camera axes in world coordinates, in the order
    [ r20 r21 r22 t2 f ]      (down, right, back); column 3: camera centre; column 4: the
                              full-resolution image height, width and focal length (pixels).

So the camera looks along -column 2 ("back" points behind it). In OpenCV axes (x right,
y down, z forward) the camera-to-world rotation is [col 1, col 0, -col 2]. Views are ordered
like the sorted image file names, as in the LLFF tools. Coordinates are returned as stored:
no recentring or rescaling (NeRF's `recenter_poses` / bound scaling are training choices).
A missing `images_{factor}/` is made from `images/` when read (`mfsample.data.downscaled`).
"""

import numpy as np

from mfsample import fingerprints
from mfsample.camera import Camera
from mfsample.data import _io, downscaled
from mfsample.data.views import Views

# LLFF (down, right, back) columns -> OpenCV (right, down, forward) columns.
LLFF_TO_CV = np.array([[0.0, 1.0, 0.0],
                       [1.0, 0.0, 0.0],
                       [0.0, 0.0, -1.0]])


def load_llff(path, *, factor=8, make_downscaled=True):
  """Loads an LLFF forward-facing capture.

  Args:
    path: folder holding `poses_bounds.npy` and `images_{factor}/` (`images/` for factor 1).
    factor: which downsampled image folder to read. Intrinsics are scaled by the ratio of
      the actual image size to the (h, w) stored in the poses, per axis.
    make_downscaled: when `images_{factor}/` is missing, make it from `images/`
      (`mfsample.data.downscaled`: Lanczos, written beside it once, with a log line);
      False: refuse it.

  Returns:
    (views, bounds): `Views` (images [V, H, W, 3] float32, alphas None, cameras in OpenCV
    axes, names = image file stems) and bounds [V, 2] float32 (near, far) scene depths
    along each camera's viewing axis, in world units.

  Raises:
    FileNotFoundError: a missing folder, `poses_bounds.npy` or image folder.
    DatasetError (a ValueError): wrong array shape, image count or sizes, non-finite or
      non-rigid poses, invalid bounds.
  """
  root = _io.require_dir(path, "LLFF dataset folder")
  if (not isinstance(factor, (int, np.integer)) or isinstance(factor, bool) or factor < 1):
    raise ValueError(f"factor must be an integer >= 1, got {factor!r}")
  poses_path = _io.require_file(root / "poses_bounds.npy", "LLFF poses file")
  try:
    data = np.load(poses_path, allow_pickle=False)
  except (ValueError, OSError, EOFError) as e:
    raise _io.DatasetError(f"{poses_path}: cannot read ({e}).") from e
  if not isinstance(data, np.ndarray):  # np.load opens an .npz archive under any name
    data.close()
    raise _io.DatasetError(f"{poses_path}: an .npz archive, not a .npy array; LLFF stores one "
                           "[V, 17] array (np.save).")
  if not (np.issubdtype(data.dtype, np.floating) or np.issubdtype(data.dtype, np.integer)):
    raise _io.DatasetError(f"{poses_path}: expected a real number array, got dtype "
                           f"{data.dtype}.")
  if data.ndim != 2 or data.shape[1] != 17 or data.shape[0] < 1:
    raise _io.DatasetError(f"{poses_path}: expected an array of shape [V, 17], got "
                           f"{data.shape}.")
  data = data.astype(np.float64)
  if not np.all(np.isfinite(data)):
    bad = int(np.argwhere(~np.isfinite(data))[0, 0])
    raise _io.DatasetError(f"{poses_path}: row {bad} has non-finite entries.")
  mats = data[:, :15].reshape(-1, 3, 5)
  bounds = data[:, 15:]
  if np.any(bounds[:, 0] <= 0) or np.any(bounds[:, 1] <= bounds[:, 0]):
    bad = int(np.argwhere((bounds[:, 0] <= 0) | (bounds[:, 1] <= bounds[:, 0]))[0, 0])
    raise _io.DatasetError(f"{poses_path}: row {bad} has invalid bounds near={bounds[bad, 0]}, "
                           f"far={bounds[bad, 1]} (need 0 < near < far).")

  if factor == 1:
    image_dir = _io.require_dir(root / "images", "image folder for factor=1")
  else:
    image_dir = downscaled.image_folder(
        root, factor, lambda: [(f, f.name) for f in _image_files(root / "images")],
        make=make_downscaled)
  fingerprints.note(image_dir)  # its listing pairs the images with the poses
  files = _image_files(image_dir)
  if len(files) != len(mats):
    raise _io.DatasetError(f"{image_dir}: {len(files)} images but {poses_path} has "
                           f"{len(mats)} poses.")
  _io.unique_names([f.stem for f in files], image_dir, "file stem")
  images = []
  for file in files:
    color, _ = _io.read_image(file)
    if images and color.shape != images[0].shape:
      raise _io.DatasetError(
          f"{file}: image is {color.shape[1]}x{color.shape[0]} but {files[0].name} is "
          f"{images[0].shape[1]}x{images[0].shape[0]}; all images must share one size.")
    images.append(color)
  height, width = images[0].shape[:2]

  c2w = np.zeros((len(mats), 4, 4))
  for v, mat in enumerate(mats):
    where = f"{poses_path} row {v}"
    rot = mat[:, :3] @ LLFF_TO_CV
    c2w[v] = _io.validate_rigid(np.concatenate([rot, mat[:, 3:4]], axis=1), where)
    h, w, f = mat[:, 4]
    if h <= 0 or w <= 0 or f <= 0:
      raise _io.DatasetError(f"{where}: invalid (h, w, focal) = ({h}, {w}, {f}).")
    # Per-axis scale: folders made by LLFF's minify round the image size.
    _io.check_scaled_copy((height, width), (h, w), files[v], where)
  hwf = mats[:, :, 4]
  sx, sy = width / hwf[:, 1], height / hwf[:, 0]
  w2c = _io.invert_rigid(c2w).astype(np.float32)
  cameras = Camera.create(w2c, (hwf[:, 2] * sx).astype(np.float32),
                          (hwf[:, 2] * sy).astype(np.float32), 0.5 * width, 0.5 * height,
                          width, height)
  views = Views(images=np.stack(images).astype(np.float32), cameras=cameras,
                names=tuple(f.stem for f in files))
  return views, bounds.astype(np.float32)


def _image_files(folder):
  """The image files of a folder, sorted by name (the order of the poses)."""
  return sorted(p for p in folder.iterdir()
                if p.is_file() and p.suffix.lower() in _io.IMAGE_SUFFIXES)


def poses_bounds_from_cameras(cameras, bounds):
  """Inverse of the loader's pose conversion: cameras (`Camera`) -> a [V, 17] `poses_bounds` array.

  Useful to write synthetic LLFF folders (tests, exports). The stored (h, w, f) are the
  camera's own size and fx; the principal point must be centred and fx == fy.

  Args:
    cameras: a batched `Camera`.
    bounds: [V, 2] (near, far).
  """
  if not isinstance(cameras, Camera) or len(cameras.batch_shape) != 1:
    raise ValueError("cameras must be a Camera batched over one axis [V]")
  num = cameras.batch_shape[0]
  bounds = np.asarray(bounds, np.float64)
  if bounds.shape != (num, 2):
    raise ValueError(f"bounds must have shape [V={num}, 2] (near, far), got "
                     f"{list(bounds.shape)}")
  # The format stores one focal length and no principal point: anything else would be lost.
  k = {n: np.asarray(getattr(cameras, n), np.float64) for n in ("fx", "fy", "cx", "cy")}
  for name, want in (("fy", k["fx"]), ("cx", 0.5 * cameras.width),
                     ("cy", 0.5 * cameras.height)):
    value, want = np.broadcast_arrays(k[name], want)
    off = np.abs(value - want) > 1e-5 * np.maximum(np.abs(want), 1.0)
    if np.any(off):
      i = int(np.argmax(off))
      raise ValueError(f"cameras.{name}[{i}] = {value[i]}, but LLFF stores one focal length and "
                       f"a centred principal point: it must be {want[i]}")
  w2c = np.asarray(cameras.world_to_camera, np.float64)
  c2w = _io.invert_rigid(w2c)
  rot = c2w[:, :3, :3] @ LLFF_TO_CV  # symmetric and orthogonal: its own inverse
  fx = k["fx"]
  hwf = np.stack([np.full_like(fx, cameras.height), np.full_like(fx, cameras.width), fx], -1)
  mats = np.concatenate([rot, c2w[:, :3, 3:4], hwf[:, :, None]], axis=-1)
  return np.concatenate([mats.reshape(-1, 15), bounds], axis=-1)
