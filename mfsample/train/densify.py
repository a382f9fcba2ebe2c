"""Adaptive density control of 3DGS (Kerbl et al. 2023, Sec. 5.2), on the host.

Clone small Gaussians and split large ones where the screen-space gradient is large, prune
transparent (and, later in training, huge) ones, and periodically reset opacities. Shapes
change, so this runs on the host in numpy between jitted steps; the result is re-padded to
a capacity bucket (`model.capacity_bucket`) so the step recompiles only when a bucket
grows.

Everything indexed by Gaussian moves together: mean parameters, B_hat entries and signs,
Adam's moments and the statistics. Rows are kept in the order: surviving old rows, clones,
split children. New Gaussians get fresh small B_hat entries with fresh random signs (not
copies, as in the authors' code) and zero Adam moments (as 3DGS does for new points).
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample.model import (
    Model,
    Params,
    capacity_bucket,
    init_b_hat,
    model_group_shapes,
    padding_values,
)
from mfsample.train.optim import map_moments
from mfsample.train.step import DensifyStats, TrainState


class DensifyReport(NamedTuple):
  """What one densification did (host ints)."""

  cloned: int
  split: int
  pruned: int
  live: int
  capacity: int


def _host(tree):
  return jax.tree.map(np.asarray, tree)


def _assemble(old, keep, new_rows, capacity, pad_rows):
  """[kept old rows; new rows; padding] for one array (numpy)."""
  parts = [old[keep]] + ([new_rows] if new_rows is not None else [])
  body = np.concatenate(parts, axis=0)
  pad = pad_rows[: capacity - body.shape[0]]
  return np.concatenate([body, pad.astype(body.dtype)], axis=0)


def densify_and_prune(state: TrainState, *, rng, grad_threshold, percent_dense, extent,
                      min_opacity, init_scales, max_gaussians, prune_big=False,
                      max_screen_size=0.0, max_world_size=0.1, split_count=2):
  """One 3DGS densification + pruning round.

  Args:
    state: `TrainState` (its `stats` hold the gradients since the last round).
    rng: `np.random.Generator` for the split positions and the new B_hat entries / signs
      (host-side: shapes change at every call, eager JAX ops would compile each time).
    grad_threshold: average NDC gradient norm above which a Gaussian is densified (2e-4).
    percent_dense: Gaussians with max scale <= percent_dense * extent are cloned, larger
      ones split (0.01).
    extent: scene extent.
    min_opacity: prune opacity below this (3DGS 0.005; authors 0.01).
    init_scales: {group: float} for fresh B_hat entries (`model.init_b_hat`).
    max_gaussians: live Gaussians never exceed this; when the candidates would, the ones
      with the largest gradients are densified first.
    prune_big: also prune Gaussians larger than `max_world_size` x extent and, if
      `max_screen_size` > 0, with a screen radius above it (pixels).
    split_count: children per split Gaussian (3DGS: 2).

  Returns:
    (new `TrainState` with zeroed statistics, `DensifyReport`).
  """
  model = state.model
  mean = _host(model.params.mean)
  b_hat = _host(model.params.b_hat)
  signs = _host(model.signs)
  mask = np.asarray(model.mask)
  stats = _host(state.stats)
  capacity = mask.shape[0]

  count = stats.count
  grads = np.where(count > 0, stats.grad_accum / np.maximum(count, 1), 0.0)
  scale_max = np.exp(mean["log_scales"]).max(axis=1)
  small = scale_max <= percent_dense * extent
  opacity = 1.0 / (1.0 + np.exp(-mean["opacity_logits"]))
  prune = mask & (opacity < min_opacity)
  if prune_big:
    prune |= mask & (scale_max > max_world_size * extent)
    if max_screen_size > 0:
      prune |= mask & (stats.max_radii > max_screen_size)
  # 3DGS prunes after densifying, so copies of a pruned Gaussian (same opacity) are pruned
  # too: a Gaussian about to be pruned is not densified at all.
  candidate = mask & (grads >= grad_threshold) & ~prune
  clone = candidate & small
  split = candidate & ~small

  # Respect the cap: every clone adds 1, every split adds split_count - 1.
  room = max(int(max_gaussians) - int(mask.sum()), 0)
  order = np.argsort(-np.where(candidate, grads, -np.inf), kind="stable")
  cost = np.where(clone, 1, split_count - 1)[order]
  accepted = order[(np.cumsum(cost) <= room) & candidate[order]]
  chosen = np.zeros_like(mask)
  chosen[accepted] = True
  clone &= chosen
  split &= chosen

  # Split parents are replaced by their children; a cloned Gaussian keeps its original.
  keep = np.flatnonzero(mask & ~prune & ~split)
  clone_idx = np.flatnonzero(clone)
  split_idx = np.flatnonzero(split)

  # New rows of the mean: clones copy, split children sample inside their parent.
  parent = np.concatenate([clone_idx, np.repeat(split_idx, split_count)])
  new_mean = {g: v[parent] for g, v in mean.items()}
  if len(split_idx):
    n_children = len(split_idx) * split_count
    scales = np.exp(mean["log_scales"][split_idx]).repeat(split_count, axis=0)
    rot = _rotmat(mean["quats"][split_idx]).repeat(split_count, axis=0)
    local = rng.normal(size=(n_children, 3)) * scales
    sl = slice(len(clone_idx), None)
    new_mean["means"][sl] = (mean["means"][split_idx].repeat(split_count, axis=0)
                             + np.einsum("nij,nj->ni", rot, local))
    new_mean["log_scales"][sl] = np.log(scales / (0.8 * split_count))

  num_new = len(parent)
  live = len(keep) + num_new
  new_capacity = max(capacity, capacity_bucket(live))
  shapes = model_group_shapes(model)
  pad_mean = padding_values(shapes, new_capacity)
  mean_out = {g: _assemble(mean[g], keep, new_mean[g], new_capacity, pad_mean[g])
              for g in mean}
  fresh_b_hat, fresh_signs = init_b_hat(rng, num_new, shapes, model.spec, init_scales)

  def zeros_like_rows(x):
    return np.zeros((new_capacity,) + x.shape[1:], x.dtype)

  b_hat_out = {g: _assemble(b_hat[g], keep, fresh_b_hat[g].astype(b_hat[g].dtype),
                            new_capacity, zeros_like_rows(b_hat[g])) for g in b_hat}
  signs_out = {g: _assemble(signs[g], keep, fresh_signs[g].astype(signs[g].dtype),
                            new_capacity, zeros_like_rows(signs[g])) for g in signs}

  def realign(tree):  # Adam moments: kept rows move with their Gaussian, new rows are 0
    def one(x):
      x = np.asarray(x)
      return jnp.asarray(_assemble(x, keep, np.zeros((num_new,) + x.shape[1:], x.dtype),
                                   new_capacity, zeros_like_rows(x)))
    return jax.tree.map(one, tree)

  new_model = Model(
      params=Params(mean=jax.tree.map(jnp.asarray, mean_out),
                    b_hat=jax.tree.map(jnp.asarray, b_hat_out)),
      signs=jax.tree.map(jnp.asarray, signs_out),
      mask=jnp.asarray(np.arange(new_capacity) < live),
      sh_degree=model.sh_degree,
      spec=model.spec,
  )
  new_state = state._replace(model=new_model,
                             opt_state=map_moments(state.opt_state, realign),
                             stats=DensifyStats.zeros(new_capacity))
  report = DensifyReport(cloned=len(clone_idx), split=len(split_idx),
                         pruned=int(prune.sum()), live=live, capacity=new_capacity)
  return new_state, report


def _rotmat(quats):
  """[N, 4] (w, x, y, z), any norm -> [N, 3, 3] rotation matrices (numpy; zero -> identity)."""
  q = np.asarray(quats, np.float64)
  norm = np.linalg.norm(q, axis=-1, keepdims=True)
  q = np.where(norm > 1e-12, q / np.maximum(norm, 1e-12), np.array([1.0, 0.0, 0.0, 0.0]))
  w, x, y, z = q.T
  return np.stack([
      np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
      np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
      np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
  ], axis=-2)


def reset_opacity(state: TrainState, max_opacity=0.01):
  """3DGS opacity reset: opacity = min(opacity, max_opacity), opacity moments zeroed.

  Lets training remove floaters: Gaussians that matter regain opacity quickly, the others
  fall below the pruning threshold. B_hat of the opacity logits is left as it is.
  """
  model = state.model
  cap = float(np.log(max_opacity / (1.0 - max_opacity)))
  mean = dict(model.params.mean)
  mean["opacity_logits"] = jnp.minimum(mean["opacity_logits"], cap)

  def zero_opacity(tree):
    tree_mean = dict(tree.mean)
    tree_mean["opacity_logits"] = jnp.zeros_like(tree_mean["opacity_logits"])
    return tree._replace(mean=tree_mean)

  return state._replace(model=model.replace(params=model.params._replace(mean=mean)),
                        opt_state=map_moments(state.opt_state, zero_opacity))


def grow_capacity(state: TrainState, capacity):
  """Pads every per-Gaussian array of `state` to `capacity` rows (no-op if not larger)."""
  if capacity <= state.model.capacity:
    return state
  return _pad_state(state, capacity)


def _pad_state(state, capacity):
  model = state.model
  old = model.capacity
  extra = capacity - old
  shapes = model_group_shapes(model)
  pad_mean = padding_values(shapes, extra)
  mean = {g: jnp.concatenate([v, pad_mean[g].astype(v.dtype)]) for g, v in
          model.params.mean.items()}

  def pad(x):
    return jnp.concatenate([x, jnp.zeros((extra,) + x.shape[1:], x.dtype)])

  new_model = model.replace(
      params=Params(mean=mean, b_hat=jax.tree.map(pad, model.params.b_hat)),
      signs=jax.tree.map(pad, model.signs),
      mask=jnp.concatenate([model.mask, jnp.zeros((extra,), bool)]))
  return state._replace(model=new_model, opt_state=map_moments(state.opt_state,
                                                               lambda t: jax.tree.map(pad, t)),
                        stats=jax.tree.map(pad, state.stats))
