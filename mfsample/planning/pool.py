"""The data of a planning run: candidate pool, test views, and (when there is one) an oracle.

A pool is a dataset of any kind (`mfsample.data.DATA_KINDS`, `load_dataset`): its training
views are the candidates, its test views the held-out ones. A kind that offers an oracle (a
built-in Mitsuba scene, synthetic Gaussians) captures any new pose, so the optimising
strategies can run; a dataset of files is a fixed pool (only the selection strategies run),
and a capture with SfM points brings them, for round models that start from them.
"""

from collections.abc import Callable
from typing import NamedTuple

import jax.numpy as jnp

from mfsample.camera import Camera
from mfsample.data.datasets import DataSpec, load_dataset
from mfsample.data.views import Views
from mfsample.planning import poses


class Pool(NamedTuple):
  """Everything a planning run needs to know about the scene.

  Attributes:
    name: scene name (for tables and figures).
    candidates: `Views` of the candidate pool (images and cameras).
    test: held-out `Views`.
    background: RGB the images are composited on.
    bounds: (low [3], high [3]) box holding the scene: the random initial point cloud and
      the ACP grid live in it.
    sphere: `poses.SphereSpec` of the camera sphere (always set; for a fixed pool it is
      fitted to the candidates and used only for figures).
    oracle: camera -> [H, W, 3] ground-truth image, or None for a fixed pool.
    points: the sparse SfM `PointCloud` of a capture (for round models whose `init_from` is
      "points"), else None.
  """

  name: str
  candidates: Views
  test: Views
  background: tuple
  bounds: tuple
  sphere: poses.SphereSpec
  oracle: Callable | None
  points: object = None


def make_pool(spec: DataSpec) -> Pool:
  """The `Pool` of the dataset `spec` describes."""
  data = load_dataset(spec)
  return Pool(data.name, data.train, data.test, data.background, data.bounds, data.sphere,
              data.oracle, data.points)


def stack_cameras(cameras):
  """A batched `Camera` from a list of unbatched ones (same image size)."""
  first = cameras[0]
  return Camera(jnp.stack([c.world_to_camera for c in cameras]),
                jnp.stack([c.fx for c in cameras]), jnp.stack([c.fy for c in cameras]),
                jnp.stack([c.cx for c in cameras]), jnp.stack([c.cy for c in cameras]),
                first.width, first.height)
