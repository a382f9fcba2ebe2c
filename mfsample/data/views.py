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

  def validate(self):
    """Raises ValueError naming the field unless the fields agree: images [V, H, W, 3] of
    real numbers, cameras batched over [V] with the images' size, alphas, depths and
    depth_codes [V, H, W] or None, names empty or V distinct strings. Returns the views."""
    images = self.images
    if np.ndim(images) != 4 or np.shape(images)[-1] != 3:
      raise ValueError(f"Views.images must have shape [V, H, W, 3], got {list(np.shape(images))}")
    num, height, width = np.shape(images)[:3]
    if not np.issubdtype(np.asarray(images).dtype, np.floating):
      raise ValueError(f"Views.images must be floats in [0, 1], got dtype "
                       f"{np.asarray(images).dtype}")
    cams = self.cameras
    if not isinstance(cams, Camera) or cams.batch_shape != (num,) or (
        cams.height, cams.width) != (height, width):
      got = (f"batch {cams.batch_shape}, {cams.width}x{cams.height}" if isinstance(cams, Camera)
             else type(cams).__name__)
      raise ValueError(f"Views.cameras must be a Camera batched over [{num}] with the images' "
                       f"size {width}x{height}, got {got}")
    for name in ("alphas", "depths", "depth_codes"):
      value = getattr(self, name)
      if value is not None and tuple(np.shape(value)) != (num, height, width):
        raise ValueError(f"Views.{name} must have shape [{num}, {height}, {width}] or be None, "
                         f"got {list(np.shape(value))}")
    if self.names:
      if len(self.names) != num:
        raise ValueError(f"Views.names must hold {num} names (one per view) or none, got "
                         f"{len(self.names)}")
      repeated = sorted({n for n in self.names if self.names.count(n) > 1})
      if repeated:
        raise ValueError(f"Views.names repeats {repeated[0]!r}: names identify the views")
    return self

  def subset(self, indices):
    """The views at `indices` (a sequence of ints), in that order."""
    idx = np.asarray(indices, dtype=np.int64)
    pick = lambda x: None if x is None else x[idx]
    names = tuple(self.names[i] for i in idx) if self.names else ()
    return Views(self.images[idx], self.cameras[idx], pick(self.alphas), pick(self.depths),
                 names, pick(self.depth_codes))
