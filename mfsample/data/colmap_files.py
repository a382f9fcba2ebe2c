"""A COLMAP sparse model's files checked before pycolmap reads them.

pycolmap trusts the counts in a binary file: it reserves memory for the number of points
or track elements a header declares and reads on past the end of a truncated file, so a
points3D.bin a few bytes short can exhaust the memory (`MemoryError std::bad_alloc`, or the
process killed) or loop forever, and a camera record cut short is read with leftover
values. Its text reader wraps a colour of 300 to 44 and reads the image name `my photo.jpg`
as `my`. Reading the files again in full here would duplicate pycolmap, so this module only
*walks* them, cheaply, and refuses what pycolmap would misread, naming the file, the record
and the field:

* binary files (`cameras`, `images`, `points3D`, and `rigs`, `frames` of COLMAP 3.12+): every
  record's fixed part and declared lengths must fit in the file, the last record must end at
  the end of the file, camera models must be known, and images must refer to cameras the
  model has. The walk reads a few integers per record (`struct.unpack_from` on a memory
  map), so it costs a fraction of pycolmap's own reading.
* text files: image names without spaces, images referring to known cameras, colours in
  0..255, as many camera parameters as the camera model has.
* in both: camera parameters must be finite (pycolmap's text reader fails without naming
  the camera; its binary reader keeps a NaN focal length).

The layouts are COLMAP's documented ones (little-endian; `doc/format.rst` and
`src/colmap/scene/reconstruction_io_binary.cc` of COLMAP).
"""

import functools
import math
import mmap
import struct
from pathlib import Path

from mfsample.data._io import DatasetError

# Fixed parts of the binary records, in bytes.
_CAMERA_FIXED = 4 + 4 + 8 + 8  # camera_id u32, model_id i32, width u64, height u64; params f64
_IMAGE_FIXED = 4 + 7 * 8 + 4  # image_id u32, qvec, tvec, camera_id u32; name\0; num_points2D
_POINT2D = 8 + 8 + 8  # x, y f64, point3D_id i64
_POINT3D_FIXED = 8 + 3 * 8 + 3 + 8 + 8  # id u64, xyz, rgb u8, error f64, track_length u64
_TRACK_ELEMENT = 4 + 4  # image_id u32, point2D_idx u32
_RIG_FIXED = 4 + 4  # rig_id u32, num_sensors u32
_SENSOR_ID = 4 + 4  # type i32, id u32
_POSE = 7 * 8  # quaternion (w, x, y, z), translation
_FRAME_FIXED = 4 + 4 + _POSE + 4  # frame_id, rig_id, rig_from_world, num_data_ids u32
_DATA_ID = 4 + 4 + 8  # sensor type i32, sensor id u32, data id u64


@functools.cache
def camera_model_params():
  """{COLMAP camera model id: its parameters' names}, from pycolmap (what it will read)."""
  import pycolmap

  out = {}
  for model in pycolmap.CameraModelId.__members__.values():
    if int(model) < 0:
      continue
    camera = pycolmap.Camera(model=model, width=1, height=1)
    out[int(model)] = tuple(name.strip() for name in camera.params_info.split(","))
  return out


@functools.cache
def camera_model_ids():
  """{COLMAP camera model name: its id}, from pycolmap."""
  import pycolmap

  return {name: int(model) for name, model in pycolmap.CameraModelId.__members__.items()
          if int(model) >= 0}


def check_model_files(sparse):
  """Walks the model files of the folder `sparse` (binary or text, as pycolmap picks them:
  binary when `cameras.bin`, `images.bin` and `points3D.bin` all exist).

  Raises:
    DatasetError: naming the file, the record and what is wrong.
  """
  sparse = Path(sparse)
  if all((sparse / f"{name}.bin").is_file() for name in ("cameras", "images", "points3D")):
    camera_ids = _walk_cameras(sparse / "cameras.bin")
    _walk_images(sparse / "images.bin", camera_ids)
    _walk_points(sparse / "points3D.bin")
    for name, walk in (("rigs", _walk_rigs), ("frames", _walk_frames)):
      if (sparse / f"{name}.bin").is_file():
        walk(sparse / f"{name}.bin")
  else:
    camera_ids = _scan_cameras_text(sparse / "cameras.txt")
    _scan_images_text(sparse / "images.txt", camera_ids)
    _scan_points_text(sparse / "points3D.txt")


# ------------------------------------------------------------------------- binary files


class _Walker:
  """Reads little-endian integers from a memory-mapped file, refusing to read past its end."""

  def __init__(self, path, data):
    self.path, self.data, self.pos = path, data, 0
    self.size = len(data)

  def need(self, n, what):
    if self.pos + n > self.size:
      raise DatasetError(f"{self.path}: truncated: {what} ({n} bytes from byte {self.pos}) "
                         f"runs past the end of the file (byte {self.size}).")

  def read(self, fmt, what):
    n = struct.calcsize(fmt)
    self.need(n, what)
    value = struct.unpack_from(fmt, self.data, self.pos)
    self.pos += n
    return value if len(value) > 1 else value[0]

  def skip(self, n, what):
    self.need(n, what)
    self.pos += n

  def count(self, what, minimum_record):
    """The leading record count, which must fit in the file at `minimum_record` bytes each."""
    n = self.read("<Q", f"the number of {what}")
    left = self.size - self.pos
    if n * minimum_record > left:
      raise DatasetError(f"{self.path}: declares {n} {what} of at least {minimum_record} bytes "
                         f"each, but only {left} bytes follow: a truncated or corrupt file.")
    return n

  def name(self, what):
    end = self.data.find(b"\0", self.pos)
    if end < 0:
      raise DatasetError(f"{self.path}: truncated: {what} has no terminating NUL byte before "
                         f"the end of the file.")
    raw = self.data[self.pos:end]
    self.pos = end + 1
    return raw.decode("utf-8", "replace")

  def end(self, what):
    if self.pos != self.size:
      raise DatasetError(f"{self.path}: {self.size - self.pos} bytes follow the last of the "
                         f"{what} the file declares: a corrupt file, or not a COLMAP one.")


def _walk(path, walk):
  with open(path, "rb") as f:
    size = f.seek(0, 2)
    if size == 0:
      raise DatasetError(f"{path}: the file is empty (a binary COLMAP file starts with its "
                         "record count).")
    with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
      return walk(_Walker(path, data))


def _walk_cameras(path):
  params = camera_model_params()

  def walk(w):
    ids = set()
    for i in range(w.count("cameras", _CAMERA_FIXED)):
      camera_id, model_id = w.read("<Ii", f"camera record {i}")
      w.skip(16, f"camera {camera_id} (width, height)")
      if model_id not in params:
        raise DatasetError(f"{path}: camera {camera_id} has the model id {model_id}, which "
                           f"COLMAP does not define (known: 0..{max(params)}).")
      names = params[model_id]
      values = w.read(f"<{len(names)}d", f"the {len(names)} parameters of camera {camera_id}")
      _check_params(path, camera_id, names, values if len(names) > 1 else (values,))
      ids.add(camera_id)
    w.end("cameras")
    return ids

  return _walk(path, walk)


def _walk_images(path, camera_ids):
  def walk(w):
    for i in range(w.count("images", _IMAGE_FIXED + 1 + 8)):
      image_id = w.read("<I", f"image record {i}")
      w.skip(7 * 8, f"the pose of image {image_id}")
      camera_id = w.read("<I", f"the camera id of image {image_id}")
      name = w.name(f"the name of image {image_id}")
      if camera_id not in camera_ids:
        raise DatasetError(f"{path}: image {image_id} ({name!r}) refers to camera {camera_id}, "
                           f"which cameras.bin does not hold.")
      n = w.read("<Q", f"the number of 2D points of image {name!r}")
      w.skip(n * _POINT2D, f"the {n} 2D points of image {name!r}")
    w.end("images")

  _walk(path, walk)


def _walk_points(path):
  # The one file with millions of records: a tight loop that reads only each track length.
  track_length = struct.Struct("<Q").unpack_from

  def walk(w):
    num = w.count("3D points", _POINT3D_FIXED)
    data, size, pos = w.data, w.size, w.pos
    for i in range(num):
      if pos + _POINT3D_FIXED > size:
        if i and pos > size:
          raise DatasetError(f"{path}: truncated: the track of 3D point record {i - 1} runs "
                             f"past the end of the file (byte {size}).")
        raise DatasetError(f"{path}: truncated: 3D point record {i} ({_POINT3D_FIXED} bytes "
                           f"from byte {pos}) runs past the end of the file (byte {size}).")
      pos += _POINT3D_FIXED + _TRACK_ELEMENT * track_length(data, pos + _POINT3D_FIXED - 8)[0]
    if pos > size:
      raise DatasetError(f"{path}: truncated: the track of 3D point record {num - 1} runs past "
                         f"the end of the file (byte {size}).")
    w.pos = pos
    w.end("3D points")

  _walk(path, walk)


def _walk_rigs(path):
  def walk(w):
    for i in range(w.count("rigs", _RIG_FIXED)):
      rig_id, num_sensors = w.read("<II", f"rig record {i}")
      if num_sensors > 0:
        w.skip(_SENSOR_ID, f"the reference sensor of rig {rig_id}")
      # Each further sensor: its id, a has-pose flag and the pose when the flag is set.
      w.need(max(num_sensors - 1, 0) * (_SENSOR_ID + 1), f"the {num_sensors} sensors of rig "
             f"{rig_id}")
      for _ in range(max(num_sensors - 1, 0)):
        w.skip(_SENSOR_ID, f"a sensor of rig {rig_id}")
        has_pose = w.read("<B", f"a sensor of rig {rig_id}")
        if has_pose > 1:
          raise DatasetError(f"{path}: rig {rig_id}: a sensor's has-pose flag is {has_pose}, "
                             "not 0 or 1: a corrupt file.")
        if has_pose:
          w.skip(_POSE, f"a sensor pose of rig {rig_id}")
    w.end("rigs")

  _walk(path, walk)


def _walk_frames(path):
  def walk(w):
    for i in range(w.count("frames", _FRAME_FIXED)):
      w.skip(_FRAME_FIXED - 4, f"frame record {i}")
      n = w.read("<I", f"the number of data ids of frame record {i}")
      w.skip(n * _DATA_ID, f"the {n} data ids of frame record {i}")
    w.end("frames")

  _walk(path, walk)


# ------------------------------------------------------------------------- text files


def _data_lines(path):
  """(line number, stripped line) of the non-empty, non-comment lines of a text file."""
  with open(path, encoding="utf-8", errors="replace") as f:
    for number, line in enumerate(f, start=1):
      line = line.strip()
      if line and not line.startswith("#"):
        yield number, line


def _scan_cameras_text(path):
  """Camera ids; each camera's parameters must be as many as its model has, and finite."""
  params = {name: camera_model_params()[model] for name, model in camera_model_ids().items()}
  ids = set()
  for number, line in _data_lines(path):
    fields = line.split()
    ids.add(fields[0])
    if len(fields) < 4 or fields[1] not in params:
      continue  # pycolmap reports lines it cannot parse
    where, names = f"{path} line {number}", params[fields[1]]
    if len(fields) - 4 != len(names):
      raise DatasetError(f"{where}: camera {fields[0]} ({fields[1]}) has {len(fields) - 4} "
                         f"parameters; the model has {len(names)} ({', '.join(names)}).")
    try:
      values = [float(v) for v in fields[4:]]
    except ValueError:
      continue  # pycolmap reports lines it cannot parse
    _check_params(where, fields[0], names, values)
  return ids


def _check_params(where, camera_id, names, values):
  """COLMAP camera parameters must be finite: pycolmap's text reader fails in "VerifyParams"
  without naming the camera, and its binary reader keeps a NaN focal length."""
  bad = [f"{name} = {value}" for name, value in zip(names, values, strict=True)
         if not math.isfinite(value)]
  if bad:
    raise DatasetError(f"{where}: camera {camera_id} has non-finite parameters: "
                       f"{', '.join(bad)}.")


def _scan_images_text(path, camera_ids):
  """Pose lines only: COLMAP reads the line after each pose line as its 2D points (even when
  it is empty), so the scan follows the same pairing."""
  with open(path, encoding="utf-8", errors="replace") as f:
    lines = enumerate(f, start=1)
    for number, line in lines:
      line = line.strip()
      if not line or line.startswith("#"):
        continue
      fields = line.split()
      if len(fields) > 10:
        name = line.split(maxsplit=9)[-1]
        raise DatasetError(
            f"{path} line {number}: the image name {name!r} contains a space, which COLMAP's "
            f"text format cannot hold (it would read {fields[9]!r}); convert the model to "
            "binary (colmap model_converter --output_type BIN).")
      if len(fields) == 10 and fields[8] not in camera_ids:
        raise DatasetError(f"{path} line {number}: image {fields[9]!r} refers to camera "
                           f"{fields[8]}, which cameras.txt does not hold.")
      next(lines, None)  # its 2D points


def _scan_points_text(path):
  for number, line in _data_lines(path):
    fields = line.split(maxsplit=8)
    for channel, text in zip("RGB", fields[4:7], strict=False):
      try:
        value = int(text)
      except ValueError:
        continue  # pycolmap reports lines it cannot parse
      if not 0 <= value <= 255:
        raise DatasetError(f"{path} line {number}: colour {channel} = {value} is outside "
                           "0..255 (COLMAP stores 8-bit colours).")
