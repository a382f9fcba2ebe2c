"""Cameras written in the formats that 3DGS tools and viewers read.

`export_cameras(directory, cameras, names, images=..., extra_images=...)` writes one folder:

  directory/
    transforms.json         nerfstudio: camera-to-world `transform_matrix` (OpenGL axes) and
                            PINHOLE intrinsics per frame, `file_path` = images/NAME.png
                            (`mfsample.data.load_nerfstudio` and nerfstudio's dataparser read it)
    camera_path.json        nerfstudio's render path through the cameras (`ns-render
                            camera-path --camera-path-filename ...`, the viewer's "Load Path")
    cameras.json            the 3DGS reference code's camera list (`img_name`, `position`,
                            `rotation`, `fx`, `fy`): what SuperSplat imports as camera poses
    sparse/0/cameras.txt    COLMAP text model, poses only: one PINHOLE camera per intrinsics,
    sparse/0/images.txt     one image per camera (no 2D points), an empty points3D.txt
    sparse/0/points3D.txt   (`load_colmap(directory)` and pycolmap read it)
    images/NAME.png         the images given (e.g. the mean render there), if any
    {key}/NAME.png          further images per camera (e.g. "uncertainty": the U map)

Conventions (each as the reading tool defines it):

* nerfstudio `transform_matrix` and `camera_path.json` `camera_to_world`: camera-to-world,
  camera axes x right, y up, z backward (OpenGL), flattened row-major in the camera path;
  the camera path's `fov` is the vertical field of view in degrees, 2 atan(h / (2 fy)).
  nerfstudio renders a camera path with square pixels and a centred principal point
  (`get_path_from_json`), so fx != fy or an off-centre cx, cy is approximated there; the
  transforms.json frames keep them exactly.
* cameras.json: `position` is the camera centre, `rotation` the camera-to-world rotation in
  OpenCV axes (rows), as the 3DGS reference code's `camera_to_JSON` writes them.
* COLMAP images.txt: the world-to-camera rotation as a quaternion (QW, QX, QY, QZ) and the
  translation; cameras.txt: PINHOLE fx fy cx cy, pixel centres at +0.5 as in mfsample.

Poses are written in the world of the cameras given (for a capture, the capture's own: the
frame of its `transforms.json`, or of its COLMAP model); nothing is re-centred or scaled.
"""

from pathlib import Path

import numpy as np

from mfsample._json import atomic_path, write_json, write_text
from mfsample.camera import Camera
from mfsample.data.nerfstudio import GL_TO_CV, frames_of


def cameras_from_poses(world_to_camera, intrinsics):
  """A batched `Camera` from a list of poses and intrinsics, as run records hold them.

  Args:
    world_to_camera: [V, 4, 4] nested lists or array (e.g. a planning run record's
      "world_to_camera", or the "world_to_camera" of next_views.json's entries).
    intrinsics: {"fx", "fy", "cx", "cy", "width", "height"}: numbers shared by every view, or
      per view lists for fx, fy, cx, cy (next_views.json's "intrinsics").
  """
  w2c = np.asarray(world_to_camera, np.float32).reshape(-1, 4, 4)
  k = {key: np.broadcast_to(np.asarray(intrinsics[key], np.float32), (len(w2c),))
       for key in ("fx", "fy", "cx", "cy")}
  return Camera.create(w2c, k["fx"], k["fy"], k["cx"], k["cy"], int(intrinsics["width"]),
                       int(intrinsics["height"]))


def _batch(cameras):
  return cameras if cameras.batch_shape else Camera(
      cameras.world_to_camera[None], cameras.fx[None], cameras.fy[None], cameras.cx[None],
      cameras.cy[None], cameras.width, cameras.height)


def _safe(name):
  return "".join(c if c.isalnum() or c in "-_." else "_" for c in str(name)) or "view"


def _c2w_gl(cameras):
  """[V, 4, 4] float64 camera-to-world in OpenGL axes (the true inverse of the pose)."""
  w2c = np.asarray(cameras.world_to_camera, np.float64).reshape(-1, 4, 4)
  return np.linalg.inv(w2c) @ GL_TO_CV


def vertical_fov_degrees(cameras):
  """[V] vertical field of view in degrees: 2 atan(h / (2 fy))."""
  fy = np.asarray(cameras.fy, np.float64).reshape(-1)
  return np.degrees(2.0 * np.arctan(0.5 * cameras.height / fy))


def similarity_transform(cameras, transform):
  """`cameras` moved by a similarity `transform` ([4, 4]: s R | t, s > 0): centre c -> s R c + t,
  orientation R_c2w -> R R_c2w; intrinsics unchanged, so a point p and its image M p project
  to the same pixel (e.g. into the world of a model nerfstudio trained: `nerfstudio_world`)."""
  m = np.asarray(transform, np.float64)
  scale = np.cbrt(np.linalg.det(m[:3, :3]))
  if not np.isfinite(scale) or scale <= 0:
    raise ValueError(f"transform must be a similarity with a positive scale, got {m.tolist()}")
  c2w = np.linalg.inv(np.asarray(cameras.world_to_camera, np.float64).reshape(-1, 4, 4))
  moved = np.einsum("ij,vjk->vik", m, c2w)
  moved[:, :3, :3] /= scale
  return Camera.create(np.linalg.inv(moved).astype(np.float32), cameras.fx, cameras.fy,
                       cameras.cx, cameras.cy, cameras.width, cameras.height)


def nerfstudio_world(dataparser_transforms, capture=None):
  """[4, 4] similarity from a nerfstudio capture's world to that of a model nerfstudio trained.

  nerfstudio's trainers re-centre, orient and scale the capture and save how in their output
  folder's `dataparser_transforms.json`: {"transform": [3, 4], "scale": s}, which maps the
  *original* world (before the capture's `applied_transform`) to the model's:
  p_model = s (T p_original). For cameras in the capture's world (`load_nerfstudio`'s default
  frame) the capture's `applied_transform` A is undone first: M = diag(s, s, s, 1) T A^-1.

  Args:
    dataparser_transforms: path of dataparser_transforms.json, or its dict.
    capture: the capture folder (or its transforms.json) for its applied_transform; None
      for cameras already in the original world (`load_nerfstudio(..., frame="original")`).
  """
  from mfsample.data import _io
  from mfsample.data.nerfstudio import applied_transform

  meta = (dataparser_transforms if isinstance(dataparser_transforms, dict)
          else _io.read_json(dataparser_transforms))
  where = "dataparser_transforms.json" if isinstance(dataparser_transforms, dict) else str(
      dataparser_transforms)
  if "transform" not in meta or "scale" not in meta:
    raise _io.DatasetError(f"{where}: expected 'transform' (3 x 4) and 'scale'.")
  transform = _io.validate_rigid(meta["transform"], where, "'transform'")
  scale = _io.number(meta, "scale", where)
  undo = np.eye(4)
  if capture is not None:
    capture = Path(capture)
    applied = applied_transform(_io.read_json(
        capture if capture.suffix == ".json" else capture / "transforms.json"), str(capture))
    undo = np.linalg.inv(applied)
  return np.diag([scale, scale, scale, 1.0]) @ transform @ undo


def camera_path(cameras, *, steps_per_view=1, fps=24.0):
  """nerfstudio's camera-path dict through `cameras`, in their order.

  Each camera is a keyframe and a frame of the path; with `steps_per_view` > 1, that many
  frames lead from each camera to the next (positions linear, rotations spherical-linear),
  so frame k * steps_per_view is camera k exactly.

  Args:
    cameras: `Camera` batched over [V] (one image size).
    steps_per_view: frames per camera-to-camera transition (1: the cameras only).
    fps: frame rate written to the file; `seconds` = frames / fps.
  """
  from scipy.spatial.transform import Rotation, Slerp

  cameras = _batch(cameras)
  c2w = _c2w_gl(cameras)
  fov = vertical_fov_degrees(cameras)
  aspect = cameras.width / cameras.height
  steps = int(steps_per_view)
  if steps < 1:
    raise ValueError(f"steps_per_view must be an integer >= 1, got {steps_per_view!r}")
  frames = []
  for i in range(len(c2w)):
    frames.append((c2w[i], fov[i]))
    if i + 1 < len(c2w) and steps > 1:
      slerp = Slerp([0.0, 1.0], Rotation.from_matrix(c2w[i:i + 2, :3, :3]))
      for t in np.arange(1, steps) / steps:
        pose = np.eye(4)
        pose[:3, :3] = slerp([t]).as_matrix()[0]
        pose[:3, 3] = (1.0 - t) * c2w[i, :3, 3] + t * c2w[i + 1, :3, 3]
        frames.append((pose, (1.0 - t) * fov[i] + t * fov[i + 1]))
  flat = lambda m: np.asarray(m, np.float64).reshape(-1).tolist()
  return {
      "camera_type": "perspective",
      "render_height": int(cameras.height), "render_width": int(cameras.width),
      "fps": float(fps), "seconds": len(frames) / float(fps),
      "is_cycle": False, "smoothness_value": 0.0,
      "default_fov": float(fov[0]), "default_transition_sec": steps / float(fps),
      "keyframes": [{"matrix": flat(c2w[i]), "fov": float(fov[i]), "aspect": aspect,
                     "override_transition_enabled": False, "override_transition_sec": None}
                    for i in range(len(c2w))],
      "camera_path": [{"camera_to_world": flat(pose), "fov": float(f), "aspect": aspect}
                      for pose, f in frames],
  }


def inria_cameras(cameras, names):
  """The 3DGS reference code's `cameras.json` list (what SuperSplat imports as poses)."""
  cameras = _batch(cameras)
  c2w = np.linalg.inv(np.asarray(cameras.world_to_camera, np.float64).reshape(-1, 4, 4))
  return [{"id": i, "img_name": str(names[i]), "width": int(cameras.width),
           "height": int(cameras.height), "position": c2w[i, :3, 3].tolist(),
           "rotation": c2w[i, :3, :3].tolist(), "fx": float(cameras.fx[i]),
           "fy": float(cameras.fy[i])} for i in range(len(c2w))]


def colmap_text(cameras, image_names):
  """(cameras.txt, images.txt, points3D.txt) of a COLMAP text model of the poses alone.

  Written by hand rather than with pycolmap (an optional extra): three short text files whose
  format COLMAP documents; pycolmap reads them back in the tests.
  """
  from scipy.spatial.transform import Rotation

  cameras = _batch(cameras)
  w2c = np.asarray(cameras.world_to_camera, np.float64).reshape(-1, 4, 4)
  ks = np.stack([np.asarray(getattr(cameras, k), np.float32).reshape(-1).astype(np.float64)
                 for k in ("fx", "fy", "cx", "cy")], axis=-1)
  ids = {}
  camera_lines, image_lines = [], []
  for i in range(len(w2c)):
    key = tuple(ks[i].tolist())
    if key not in ids:
      ids[key] = len(ids) + 1
      camera_lines.append(f"{ids[key]} PINHOLE {cameras.width} {cameras.height} "
                          + " ".join(repr(v) for v in key))
    x, y, z, w = Rotation.from_matrix(w2c[i, :3, :3]).as_quat()  # scalar last
    values = (w, x, y, z, *w2c[i, :3, 3])
    image_lines.append(f"{i + 1} " + " ".join(repr(float(v)) for v in values)
                       + f" {ids[key]} {image_names[i]}")
    image_lines.append("")  # the image's 2D points: none
  cams = ("# Camera list with one line of data per camera:\n"
          "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
          f"# Number of cameras: {len(camera_lines)}\n" + "\n".join(camera_lines) + "\n")
  images = ("# Image list with two lines of data per image:\n"
            "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
            "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
            f"# Number of images: {len(w2c)}, mean observations per image: 0\n"
            + "\n".join(image_lines) + "\n")
  points = ("# 3D point list with one line of data per point:\n"
            "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
            "# Number of points: 0, mean track length: 0\n")
  return cams, images, points


def _write_png(path, image):
  import imageio.v3 as iio

  image = np.asarray(image)
  if image.dtype != np.uint8:
    image = np.round(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)
  with atomic_path(path) as tmp:
    iio.imwrite(tmp, image)


def export_cameras(directory, cameras: Camera, names=None, *, images=None, extra_images=None,
                   steps_per_view=1, fps=24.0, applied_transform=None):
  """Writes `cameras` in every format of the module docstring to `directory`.

  Args:
    directory: output folder (created if needed; its files are replaced).
    cameras: `Camera`, one or batched over [V].
    names: V view names (default view_000 ...); made file-name safe.
    images: optional [V, H, W, 3] images in [0, 1] (or uint8) of the cameras: images/NAME.png.
    extra_images: optional {folder: [V, H, W(, 3)] images}: folder/NAME.png each (e.g. U maps
      already colour-mapped).
    steps_per_view, fps: of camera_path.json (`camera_path`).
    applied_transform: optional [3, 4] recorded in transforms.json (the capture's, so that
      nerfstudio sees the cameras in the same world as the capture); the poses are written
      as given.

  Returns:
    {format: path} of the written files.
  """
  cameras = _batch(cameras)
  num = cameras.batch_shape[0]
  names = [f"view_{i:03d}" for i in range(num)] if names is None else list(names)
  if len(names) != num:
    raise ValueError(f"{len(names)} names for {num} cameras")
  stems = [_safe(n) for n in names]
  if len(set(stems)) != num:
    raise ValueError(f"view names must be distinct as file names, got {names}")
  root = Path(directory)
  root.mkdir(parents=True, exist_ok=True)
  out = {}
  for folder, batch in [("images", images), *dict(extra_images or {}).items()]:
    if batch is None:
      continue
    if len(batch) != num:
      raise ValueError(f"{folder}: {len(batch)} images for {num} cameras")
    for stem, image in zip(stems, batch, strict=True):
      _write_png(root / folder / f"{stem}.png", image)
    out[folder] = root / folder
  top, frames = frames_of(cameras, stems, per_frame_intrinsics=True)
  meta = dict(top)
  if applied_transform is not None:
    meta["applied_transform"] = np.asarray(applied_transform, np.float64)[:3].tolist()
  meta["frames"] = frames
  out["transforms"] = root / "transforms.json"
  write_json(out["transforms"], meta)
  out["camera_path"] = root / "camera_path.json"
  write_json(out["camera_path"], camera_path(cameras, steps_per_view=steps_per_view, fps=fps))
  out["inria"] = root / "cameras.json"
  write_json(out["inria"], inria_cameras(cameras, stems))
  sparse = root / "sparse" / "0"
  for name, text in zip(("cameras", "images", "points3D"),
                        colmap_text(cameras, [f"{s}.png" for s in stems]), strict=True):
    write_text(sparse / f"{name}.txt", text)
  out["colmap"] = sparse
  return out



def nerfstudio_camera_path(views_dir, dataparser_transforms, capture, out, **kwargs):
  """Rewrites the camera path of exported views for a model nerfstudio trained on `capture`.

  Args:
    views_dir: a folder written by `export_cameras` (its transforms.json, in the capture's
      world, e.g. the job's `next_views/`).
    dataparser_transforms: the trained model's dataparser_transforms.json (`nerfstudio_world`).
    capture: the nerfstudio capture the model was trained on (its applied_transform).
    out: the camera path to write (the viewer's "Load Path" lists `capture/camera_paths/`).
    **kwargs: `camera_path`'s steps_per_view and fps.

  Returns:
    `out`.
  """
  from mfsample.data.nerfstudio import load_nerfstudio

  views, _ = load_nerfstudio(views_dir)
  world = nerfstudio_world(dataparser_transforms, capture)
  write_json(out, camera_path(similarity_transform(views.cameras, world), **kwargs))
  return out
