"""ACP: active camera placement by coverage and angular uniformity (Kopanas & Drettakis 2023).

ACP places the next camera where it most improves how completely, and from how many
different directions, the scene volume is observed. Our exact score (host-side numpy):

* a regular grid of R^3 cell centres (R = 32) fills the scene's bounding box;
* camera k observes cell p when p projects inside its image in front of the near plane
  (optionally also not occluded: p's depth is at most the model's rendered expected depth
  at that pixel plus a tolerance, where the render is opaque);
* the direction from p to camera k falls into one of B direction bins, the nearest of B
  Fibonacci-sphere directions (B = 64);
* a set of cameras S scores::

    A(S) = (1 / R^3) sum_p [ 1(some camera of S observes p) + w * |bins of S at p| / B ],

  coverage plus the fraction of direction bins seen (angular uniformity);
* the next camera is the candidate c maximising the gain A(S + {c}) - A(S).
"""

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np


def grid_points(low, high, resolution=32):
  """[R^3, 3] cell centres of a regular grid filling the box [low, high] (numpy float32)."""
  low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
  ticks = [low[i] + (np.arange(resolution) + 0.5) * (high[i] - low[i]) / resolution
           for i in range(3)]
  grid = np.stack(np.meshgrid(*ticks, indexing="ij"), axis=-1)
  return grid.reshape(-1, 3).astype(np.float32)


def fibonacci_directions(num):
  """[num, 3] nearly uniform unit vectors (a Fibonacci lattice on the sphere)."""
  i = np.arange(num) + 0.5
  z = 1.0 - 2.0 * i / num
  r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
  phi = math.pi * (3.0 - math.sqrt(5.0)) * i
  return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


class Observations(NamedTuple):
  """What a batch of K cameras sees of P grid cells.

  Attributes:
    visible: [K, P] bool.
    bins: [K, P] int32 direction bin of the cell -> camera direction.
  """

  visible: np.ndarray
  bins: np.ndarray


def observe(cameras, points, directions, *, near=0.2, depth=None, alpha=None, depth_tol=0.05,
            opaque=0.5):
  """Which cells each camera observes, and from which direction bin.

  Args:
    cameras: `Camera` batched over [K].
    points: [P, 3] cell centres.
    directions: [B, 3] bin directions (`fibonacci_directions`).
    near: cells closer than this (camera z) are not observed.
    depth: optional [K, H, W] expected depths of a model's render (occlusion test).
    alpha: [K, H, W] the render's opacity; the occlusion test applies where alpha > opaque.
    depth_tol: a cell up to this far behind the rendered surface still counts as seen.
    opaque: opacity above which a pixel occludes.

  Returns:
    `Observations`.
  """
  pts = jnp.asarray(points)
  uv, z = cameras.project(jnp.broadcast_to(pts, cameras.batch_shape + pts.shape))
  uv, z = np.asarray(uv), np.asarray(z)
  w, h = cameras.width, cameras.height
  visible = ((z > near) & (uv[..., 0] >= 0) & (uv[..., 0] < w) & (uv[..., 1] >= 0)
             & (uv[..., 1] < h))
  if depth is not None:
    col = np.clip(uv[..., 0].astype(np.int64), 0, w - 1)
    row = np.clip(uv[..., 1].astype(np.int64), 0, h - 1)
    k = np.arange(len(z))[:, None]
    surface = np.asarray(depth)[k, row, col]
    opaque_px = np.asarray(alpha)[k, row, col] > opaque
    visible &= ~opaque_px | (z <= surface + depth_tol)
  points = np.asarray(points, np.float32)
  dirs_t = np.asarray(directions, np.float32).T
  bins = np.empty(visible.shape, np.int32)
  for i, center in enumerate(np.asarray(cameras.center, np.float32)):  # [P, B] at a time
    to_cam = center[None] - points
    to_cam /= np.maximum(np.linalg.norm(to_cam, axis=-1, keepdims=True), 1e-12)
    bins[i] = np.argmax(to_cam @ dirs_t, axis=-1)
  return Observations(visible, bins)


def coverage_state(obs: Observations, num_bins):
  """(covered [P] bool, seen [P, B] bool) of a set of cameras."""
  covered = np.any(obs.visible, axis=0)
  seen = np.zeros((obs.visible.shape[1], num_bins), bool)
  k, p = np.nonzero(obs.visible)
  seen[p, obs.bins[k, p]] = True
  return covered, seen


def acp_value(obs: Observations, num_bins, weight=1.0):
  """A(S) of the module docstring for the cameras of `obs`."""
  covered, seen = coverage_state(obs, num_bins)
  return float(np.mean(covered) + weight * np.mean(np.sum(seen, axis=1)) / num_bins)


def acp_gains(train: Observations, candidates: Observations, num_bins, weight=1.0):
  """[C] gains A(S + {c}) - A(S) of every candidate c over the training set S."""
  covered, seen = coverage_state(train, num_bins)
  p = np.arange(covered.shape[0])[None, :]
  new_cell = candidates.visible & ~covered[None]
  new_bin = candidates.visible & ~seen[p, candidates.bins]
  num_cells = covered.shape[0]
  return (np.sum(new_cell, axis=1) + weight * np.sum(new_bin, axis=1) / num_bins) / num_cells
