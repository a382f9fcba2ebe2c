"""The forward-facing views of the AUSE benchmark: an arc of cameras, with exact depth.

The paper measures AUSE on the light-field scenes of Yücer et al. (a few forward-facing
views, the interleaved ones for testing), whose depth is not available here. The Mitsuba
capture oracle gives the same setting with exact metric depth: `num_views` cameras on an
arc of azimuth at one height, all looking at one point of the table; the 1st, 3rd, ... views
train and the views between them test. NeRF Synthetic's depth files are 8-bit and not metric,
so they cannot serve.
"""

import math

import numpy as np

from mfsample.camera import Camera
from mfsample.config_blocks import data_spec
from mfsample.data.datasets import capture_views


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
    data: the config's `data` block (its kind must offer depth: `DataKind.offers`).
    scene_name: a `mfsample.scenes` name (ignored for data.kind "synthetic").

  Returns:
    (`Views` [num_views] with images, alphas, depths, cameras; (low [3], high [3]), the box
    of the scene where the models' random initial points go).
  """
  spec = data_spec(data).replace(scene=scene_name)
  return capture_views(spec, arc_cameras(data.arc, data.width, data.height))
