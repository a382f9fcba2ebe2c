"""Next views as files that viewers open: cameras in their formats, with a preview each.

`export_next_views` renders, for every proposed camera, the mean model's image and the
per-pixel U map (Eq. 10, colour-mapped on one scale shared by the views) and writes them with
the cameras (`mfsample.data.camera_export.export_cameras`):

  directory/
    transforms.json, camera_path.json, cameras.json, sparse/0/*.txt   the cameras
    images/NAME.png         the mean render there (what the model expects to see)
    uncertainty/NAME.png    the U map there (magma; the scale is in uncertainty.json)
    captured/NAME.png       the candidate's own photograph, when it has one
    uncertainty.json        per view: name, U, the largest per-pixel value; the colour scale

`export_planned_views` takes what a run record holds (the poses and the intrinsics) instead
of a `Camera`, so that a planning run's chosen views are one call away from the same files.
"""

import os

import jax.numpy as jnp
import numpy as np

from mfsample import view_uncertainty as unc
from mfsample._json import write_json
from mfsample.data.camera_export import cameras_from_poses, export_cameras
from mfsample.mean_render import render_mean
from mfsample.renderer.budget import render_with_budget


def colour_mapped(values, vmax, cmap="magma"):
  """[..., 3] uint8 colours of `values` on a matplotlib colour map over [0, vmax]."""
  try:
    import matplotlib
  except ImportError as err:
    raise ImportError("colour-mapped uncertainty needs matplotlib (pip install "
                      "'mfsample[plots]')") from err
  scaled = np.clip(np.asarray(values, np.float64) / max(float(vmax), 1e-30), 0.0, 1.0)
  rgba = matplotlib.colormaps[cmap](scaled)
  return np.round(rgba[..., :3] * 255.0).astype(np.uint8)


def preview(model, cameras, z, *, settings, background):
  """([V, H, W, 3] mean renders in [0, 1], [V, H, W] U maps, [V] U, settings that sufficed)."""
  bg = jnp.asarray(background, jnp.float32)
  renders, maps = [], []
  for i in range(cameras.batch_shape[0] if cameras.batch_shape else 1):
    camera = cameras[i] if cameras.batch_shape else cameras
    out, settings = render_with_budget(render_mean, settings, model, camera, bg)
    u, settings = render_with_budget(unc.uncertainty, settings, model, camera, z, background=bg)
    renders.append(np.asarray(jnp.clip(out.rgb, 0.0, 1.0)))
    maps.append(np.asarray(u.pixel_map))
  maps = np.stack(maps)
  return np.stack(renders), maps, maps.reshape(len(maps), -1).sum(axis=1), settings


def export_next_views(directory, model, cameras, z, *, settings, background, names=None,
                      images=None, applied_transform=None, steps_per_view=1, previews=None):
  """Writes the cameras, their mean renders and U maps (module docstring) to `directory`.

  Args:
    directory: output folder.
    model: the `mfsample.model.Model` whose uncertainty proposed the views.
    cameras: `Camera` batched over [V] (e.g. the top k candidates, best first).
    z: `[M, *z_shape]` samples of U (`mfsample.samplers.sample_z`).
    settings: `RenderSettings` to start from (grown on overflow).
    background: [3] colour behind the Gaussians.
    names: V view names (default view_000 ...).
    images: optional [V, H, W, 3] photographs of the cameras (candidates that have one).
    applied_transform: optional [3, 4] of the capture, recorded in transforms.json.
    steps_per_view: frames per transition of camera_path.json.
    previews: optional (renders, maps, u) that `preview` already returned for these
      cameras, model and z (then nothing is rendered here).

  Returns:
    ({format or folder: path}, the settings that sufficed).
  """
  if previews is None:
    renders, maps, u, settings = preview(model, cameras, z, settings=settings,
                                         background=background)
  else:
    renders, maps, u = previews
  vmax = max(float(maps.max()), 1e-12)
  extra = {"uncertainty": colour_mapped(maps, vmax)}
  if images is not None:
    extra["captured"] = images
  names = ([f"view_{i:03d}" for i in range(len(renders))] if names is None
           else [str(n) for n in names])
  paths = export_cameras(directory, cameras, names, images=renders, extra_images=extra,
                         steps_per_view=steps_per_view, applied_transform=applied_transform)
  paths["summary"] = os.path.join(directory, "uncertainty.json")
  write_json(paths["summary"], {
      "colour_map": "magma", "colour_scale_max": vmax, "samples": int(z.shape[0]),
      "views": [{"name": n, "u": float(u[i]), "max_pixel": float(maps[i].max())}
                for i, n in enumerate(names)]})
  return paths, settings


def export_planned_views(directory, world_to_camera, intrinsics, *, names=None, model=None,
                         z=None, settings=None, background=(0.0, 0.0, 0.0)):
  """The views of a run record as files: the cameras, and with a model their previews.

  Args:
    directory: output folder.
    world_to_camera: [V, 4, 4] nested lists (a planning run record's "world_to_camera").
    intrinsics: {"fx", "fy", "cx", "cy", "width", "height"} (the pool's camera; numbers or
      per-view lists).
    names: optional V names (default view_000 ...).
    model, z, settings, background: with a model, `export_next_views` (previews and U maps);
      without one, the cameras only (`export_cameras`).

  Returns:
    {format or folder: path}.
  """
  cameras = cameras_from_poses(world_to_camera, intrinsics)
  if model is None:
    return export_cameras(directory, cameras, names)
  if z is None or settings is None:
    raise ValueError("export_planned_views with a model needs z and settings too")
  return export_next_views(directory, model, cameras, z, settings=settings,
                           background=background, names=names)[0]
