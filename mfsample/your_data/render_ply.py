"""Any 3DGS .ply rendered to PNG: from an orbit around its Gaussians or from a camera list.

`render_ply(path, cameras)` reads a file in the 3DGS layout (`mfsample.data.load_ply`: the
reference code's `point_cloud.ply`, gsplat's, the next-views job's `uncertainty_ply/` files)
and renders its Gaussians, every SH band of the file, with mfsample's renderer. `colour_by`
replaces every colour by a property of the Gaussians on magma (black the least, pale yellow
the most; the top of the scale is the 99th percentile, as in `coloured_by_uncertainty.ply`):
the job's `u_share`, `position_std` or `colour_std` of `per_gaussian.ply`, or any float
property of the file itself. `orbit_around(means, ...)` places cameras around the Gaussians;
`inria_camera_list(path)` reads the reference code's `cameras.json` (the model folder's
cameras, or the job's `next_views/cameras.json`). `experiments/render_ply.py` is the command.
"""

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks
from mfsample.camera import Camera
from mfsample.data import _io
from mfsample.data.ply import load_ply, read_vertex_table, sh_degree_of
from mfsample.model import activate
from mfsample.renderer import RenderSettings, render
from mfsample.renderer.budget import render_with_budget
from mfsample.renderer.sh import rgb_to_sh_dc
from mfsample.your_data.uncertainty_ply import share_colours

_render = jax.jit(render, static_argnames=("settings",))


def orbit_around(means, num_views=4, *, width=320, height=240, elevation_deg=20.0,
                 fov_x_deg=50.0, up=(0.0, 0.0, 1.0)):
  """`num_views` cameras evenly around Gaussians' centres, `elevation_deg` above the plane
  perpendicular to `up`, looking at their median and far enough away that the sphere holding
  90% of the centres fills the narrower field of view.

  Args:
    means: [N, 3] centres.
    num_views: cameras on the orbit (the first at azimuth 0).
    width, height: image size in pixels.
    elevation_deg: elevation above the plane (degrees).
    fov_x_deg: horizontal field of view (degrees).
    up: [3] the scene's up direction (COLMAP worlds are often -y up: (0, -1, 0)).

  Returns:
    `Camera` [num_views].
  """
  arg_checks.check_int("num_views", num_views, minimum=1)
  means = np.asarray(means, np.float64).reshape(-1, 3)
  if len(means) == 0:
    raise ValueError("means: no Gaussians to look at")
  up = np.asarray(up, np.float64)
  if up.shape != (3,) or not np.all(np.isfinite(up)) or np.linalg.norm(up) == 0:
    raise ValueError(f"up must be 3 finite numbers, not all zero, got {up.tolist()}")
  up = up / np.linalg.norm(up)
  target = np.median(means, axis=0)
  radius = max(float(np.percentile(np.linalg.norm(means - target, axis=1), 90)), 1e-6)
  fov_x = math.radians(fov_x_deg)
  fov_y = 2.0 * math.atan(math.tan(0.5 * fov_x) * height / width)
  distance = 1.05 * radius / math.sin(0.5 * min(fov_x, fov_y))
  side = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
  side /= np.linalg.norm(side)
  other = np.cross(up, side)
  azimuths = 2.0 * math.pi * np.arange(num_views) / num_views
  e = math.radians(elevation_deg)
  eyes = target + distance * (math.cos(e) * (np.cos(azimuths)[:, None] * side
                                             + np.sin(azimuths)[:, None] * other)
                              + math.sin(e) * up)
  return Camera.look_at(jnp.asarray(eyes, jnp.float32), jnp.asarray(target, jnp.float32),
                        jnp.asarray(up, jnp.float32), fov_x, width, height)


def inria_camera_list(path, *, scale=1.0):
  """The cameras of a 3DGS `cameras.json` (a list of {width, height, position, rotation
  (camera-to-world, OpenCV axes), fx, fy}), the principal point centred, every size scaled
  by `scale`.

  Returns:
    ([`Camera`], [names]).
  """
  path = Path(path)
  entries = _io.read_json(path)
  if not isinstance(entries, list) or not entries:
    raise _io.DatasetError(f"{path}: expected a non-empty list of cameras (3DGS cameras.json).")
  cameras, names = [], []
  for i, entry in enumerate(entries):
    where = f"{path}: camera {i}"
    try:
      rotation = np.asarray(entry["rotation"], np.float64)
      position = np.asarray(entry["position"], np.float64)
      c2w = np.eye(4)
      c2w[:3, :3], c2w[:3, 3] = rotation, position
      width, height = (max(1, round(_io.number(entry, k, where, integer=True) * scale))
                       for k in ("width", "height"))
      fx, fy = (_io.number(entry, k, where) * scale for k in ("fx", "fy"))
    except (KeyError, TypeError, ValueError) as e:
      if isinstance(e, _io.DatasetError):
        raise
      raise _io.DatasetError(f"{where}: needs width, height, position [3], rotation [3, 3], "
                             f"fx and fy ({type(e).__name__}: {e}).") from None
    w2c = _io.invert_rigid(_io.validate_rigid(c2w, where, "'rotation' and 'position'"))
    cameras.append(Camera.create(jnp.asarray(w2c, jnp.float32), fx, fy, 0.5 * width,
                                 0.5 * height, width, height))
    names.append(str(entry.get("img_name", i)))
  return cameras, names


def property_values(path, name, properties=None):
  """[N] float32: the vertex property `name` of `properties` (a .ply with one row per
  Gaussian of `path`, e.g. the job's `per_gaussian.ply`) or of `path` itself."""
  source = Path(properties) if properties else Path(path)
  table = read_vertex_table(source)
  if name not in table.dtype.names:
    raise _io.DatasetError(f"{source}: no vertex property {name!r} (it has "
                           f"{', '.join(table.dtype.names)}).")
  values = np.asarray(table[name], np.float64)
  if properties and len(values) != len(read_vertex_table(path)):
    raise _io.DatasetError(f"{source}: {len(values)} rows, but {path} holds "
                           f"{len(read_vertex_table(path))} Gaussians (not its companion).")
  if not np.all(np.isfinite(values)):
    raise _io.DatasetError(f"{source}: vertex property {name!r} is not finite everywhere.")
  return values


def render_ply(path, cameras, *, colour_by=None, properties=None, background=(0.0, 0.0, 0.0),
               settings=None):
  """Renders the Gaussians of a 3DGS .ply.

  Args:
    path: the .ply.
    cameras: a `Camera` (batched over [V] or not), or a list of cameras (sizes may differ).
    colour_by: optional name of a per-Gaussian property to colour by (module docstring).
    properties: optional companion .ply holding that property (default: `path` itself).
    background: [3] colour behind the Gaussians.
    settings: `RenderSettings` to start from (the budget grows on overflow).

  Returns:
    [[H, W, 3] float32 in [0, 1]] per camera.
  """
  raw = load_ply(path)
  degree = sh_degree_of(raw)
  if colour_by:
    values = property_values(path, colour_by, properties)
    live = np.ones(len(values), bool)
    raw = dict(raw, sh_dc=np.asarray(rgb_to_sh_dc(share_colours(values, live)), np.float32))
    raw.pop("sh_rest", None)
    degree = 0
  gaussians = activate({g: jnp.asarray(v) for g, v in raw.items()}, None,
                       jnp.asarray(degree, jnp.int32))
  if isinstance(cameras, Camera):
    cameras = [cameras] if not cameras.batch_shape else [
        cameras[i] for i in range(cameras.batch_shape[0])]
  bg = jnp.asarray(background, jnp.float32)
  settings = settings or RenderSettings()
  images = []
  for camera in cameras:
    out, settings = render_with_budget(_render, settings, gaussians, camera, background=bg,
                                       what=f"rendering {path}")
    images.append(np.clip(np.asarray(out.rgb, np.float32), 0.0, 1.0))
  return images


def tile(images, columns=4, gap=4, fill=1.0):
  """[H, W, 3] of images (sizes may differ) in rows of `columns`, `gap` pixels apart."""
  columns = max(1, min(int(columns), len(images)))
  rows = [images[i:i + columns] for i in range(0, len(images), columns)]
  cell_h = max(im.shape[0] for im in images)
  cell_w = max(im.shape[1] for im in images)
  out = np.full((len(rows) * (cell_h + gap) - gap, columns * (cell_w + gap) - gap, 3), fill,
                np.float32)
  for r, row in enumerate(rows):
    for c, image in enumerate(row):
      y, x = r * (cell_h + gap), c * (cell_w + gap)
      out[y:y + image.shape[0], x:x + image.shape[1]] = image
  return out
