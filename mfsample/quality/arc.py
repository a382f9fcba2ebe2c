"""The forward-facing views of the AUSE benchmark: an arc of cameras, with exact depth.

The paper measures AUSE on the light-field scenes of Yücer et al. (a few forward-facing
views, the interleaved ones for testing), whose depth is not available here. The Mitsuba
capture oracle gives the same setting with exact metric depth: `num_views` cameras on an
arc of azimuth at one height, all looking at one point of the table; the 1st, 3rd, ... views
train and the views between them test. NeRF Synthetic's depth files are 8-bit and not metric,
so they cannot serve.
"""

import math

import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.data.views import Views


def arc_cameras(arc, width, height) -> Camera:
  """`arc.num_views` cameras evenly over `arc.span_deg` of azimuth (see the config).

  Camera i sits at azimuth a_i = azimuth - span / 2 + i span / (num_views - 1) and polar
  angle p (from +z), at `distance` from `target`, looking at it with up = +z.

  Returns:
    a `Camera` batched over [num_views].
  """
  n = int(arc.num_views)
  az = math.radians(float(arc.azimuth_deg)) + math.radians(float(arc.span_deg)) * (
      np.arange(n) / (n - 1) - 0.5)
  polar = math.radians(float(arc.polar_deg))
  target = np.asarray(arc.target, np.float64)
  direction = np.stack([np.sin(polar) * np.cos(az), np.sin(polar) * np.sin(az),
                        np.full(n, np.cos(polar))], axis=-1)
  eye = target + float(arc.distance) * direction
  return Camera.look_at(eye.astype(np.float32),
                        np.broadcast_to(target, eye.shape).astype(np.float32),
                        np.array([0.0, 0.0, 1.0], np.float32), math.radians(float(arc.fov_deg)),
                        int(width), int(height))


def split(num_views):
  """(train indices, test indices): 0, 2, ..., num_views - 1 train; 1, 3, ... test."""
  idx = np.arange(int(num_views))
  return idx[0::2], idx[1::2]


def arc_views(data, scene_name):
  """The arc's views of one scene, with alphas and exact depths.

  Args:
    data: the config's `data` block.
    scene_name: a `mfsample.scenes` name (ignored for data.kind "synthetic").

  Returns:
    (`Views` [num_views] with images, alphas, depths, cameras; (low [3], high [3]), the box
    of the scene where the models' random initial points go).
  """
  cameras = arc_cameras(data.arc, data.width, data.height)
  if data.kind == "scene":
    from mfsample import scenes
    from mfsample.data import resolve_path

    scene = scenes.get_scene(scene_name)
    cache = str(resolve_path(data.cache_dir)) if data.get("cache_dir") else None
    views = scenes.capture_views(scene, cameras, spp=int(data.spp), cache_dir=cache,
                                 background=tuple(data.background), progress=data.progress)
    c, r = np.asarray(scene.center, np.float64), float(scene.radius)
    return views, (c - r, c + r)
  if data.kind == "synthetic":
    return _synthetic_views(data, cameras)
  raise ValueError(f"data.kind must be 'scene' or 'synthetic', got {data.kind!r}")


def _synthetic_views(data, cameras):
  """Random ground-truth Gaussians (an opaque shell) rendered by mfsample: depth is the
  expected depth of that render, alpha its coverage."""
  from mfsample.data.synthetic import synthetic_scene
  from mfsample.renderer import RenderSettings, render
  from mfsample.renderer.budget import render_with_budget

  syn = data.synthetic
  truth = synthetic_scene(int(syn.num_gaussians), int(syn.seed), radius=float(syn.radius))
  bg = jnp.asarray(data.background, jnp.float32)
  settings = RenderSettings(max_intersections=1 << 12)
  images, alphas, depths = [], [], []
  for i in range(len(cameras)):
    out, settings = render_with_budget(render, settings, truth, cameras[i], background=bg)
    images.append(np.clip(np.asarray(out.rgb), 0.0, 1.0))
    alphas.append(np.asarray(out.alpha))
    depths.append(np.asarray(out.expected_depth()))
  r = float(syn.radius) + 0.2
  names = tuple(f"synthetic-arc-{i}" for i in range(len(cameras)))
  return (Views(np.stack(images).astype(np.float32), cameras, np.stack(alphas),
                np.stack(depths), names), (np.full(3, -r), np.full(3, r)))
