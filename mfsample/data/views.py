"""`Views`: posed images, the common currency of loaders, the capture oracle and training."""

from typing import NamedTuple

import chex
import numpy as np

from mfsample.camera import Camera


class Views(NamedTuple):
  """V posed images of one scene.

  Attributes:
    images: [V, H, W, 3] float32 in [0, 1], composited on the dataset's background.
    cameras: a `Camera` batched over V.
    alphas: [V, H, W] float32 coverage in [0, 1], or None when unknown.
    depths: [V, H, W] float32 metric camera z-depth (0 where nothing was hit), or None.
    names: V strings identifying the frames (file stems or capture keys).
    depth_codes: [V, H, W] float32 in [0, 1], or None: a dataset's *non-metric* depth
      encoding as stored (NeRF Synthetic's `*_depth_0001.png`: normalised and inverted,
      0 on the background). Not metres; good only for rank-based checks.
  """

  images: chex.Array
  cameras: Camera
  alphas: chex.Array | None = None
  depths: chex.Array | None = None
  names: tuple = ()
  depth_codes: chex.Array | None = None

  def __len__(self):
    return self.images.shape[0]

  def replace(self, **changes):
    """A copy with some fields changed. (NamedTuple's `_replace` fails on Views: it checks
    len() against the number of fields, and `__len__` here counts views.)"""
    return Views(**{**self._asdict(), **changes})

  def subset(self, indices):
    """The views at `indices` (a sequence of ints), in that order."""
    idx = np.asarray(indices, dtype=np.int64)
    pick = lambda x: None if x is None else x[idx]
    names = tuple(self.names[i] for i in idx) if self.names else ()
    return Views(self.images[idx], self.cameras[idx], pick(self.alphas), pick(self.depths),
                 names, pick(self.depth_codes))
