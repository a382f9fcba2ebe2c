"""Stage 2: tile intersection, sorted by tile then depth, laid out in fixed-size chunks.

Every screen-space Gaussian is paired with the tiles its footprint's bounding box overlaps
(half-widths `Projected.extents`: `mfsample.renderer.projection`). The
pairs are generated in front-to-back order (Gaussians are depth-sorted first) and stably
sorted by tile, so each tile's list is depth-ordered. Each tile's list is then padded to a
multiple of `chunk_size` so that a chunk belongs to exactly one tile: the compositor then
works on dense [chunk_size, tile_size^2] blocks with no per-tile cap. The only budget is the
total padded length, `settings.max_intersections`; exceeding it is reported in `TileStats`,
never silently hidden.
"""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp


class TileStats(NamedTuple):
  """Load figures of one render (int32 scalars, or [B] under vmap)."""

  num_intersections: chex.Array  # (tile, Gaussian) pairs before padding
  num_padded: chex.Array  # pairs after padding each tile to a multiple of chunk_size
  max_tile_load: chex.Array  # Gaussians in the busiest tile
  overflow: chex.Array  # bool: num_padded > settings.max_intersections (image incomplete)


class TileLayout(NamedTuple):
  """Chunked intersection lists. B = settings.max_chunks, C = settings.chunk_size."""

  gaussian_ids: chex.Array  # [B, C] int32 index into the input Gaussians (0 on padding)
  live: chex.Array  # [B, C] bool, False on padding
  chunk_tile: chex.Array  # [B] int32 tile index of each chunk (num_tiles on unused chunks)
  num_chunks: chex.Array  # int32 scalar: chunks in use (<= B unless overflowing)
  stats: TileStats


def tile_grid(width, height, tile_size):
  """(tiles_x, tiles_y) covering the image."""
  return -(-width // tile_size), -(-height // tile_size)


def tile_bounds(means2d, extents, width, height, tile_size):
  """Inclusive-exclusive tile ranges [x0, x1) x [y0, y1) of each Gaussian's bounding box.

  The box covers every pixel centre (j + 0.5, i + 0.5) within `extents` [N, 2] (x and y
  half-widths) of the mean, plus half a pixel of slack for rounding.
  """
  tiles_x, tiles_y = tile_grid(width, height, tile_size)
  r = extents + 0.5

  def lo(c, r, n):
    return jnp.clip(jnp.floor((c - r - 0.5) / tile_size), 0, n).astype(jnp.int32)

  def hi(c, r, n):
    return jnp.clip(jnp.floor((c + r - 0.5) / tile_size) + 1, 0, n).astype(jnp.int32)

  u, v, ru, rv = means2d[:, 0], means2d[:, 1], r[:, 0], r[:, 1]
  return lo(u, ru, tiles_x), hi(u, ru, tiles_x), lo(v, rv, tiles_y), hi(v, rv, tiles_y)


def intersect_tiles(projected, width, height, settings):
  """Builds the chunked, tile-then-depth sorted intersection lists.

  Args:
    projected: `Projected` from stage 1 (gradients are not needed here).
    width, height: image size (static).
    settings: `RenderSettings`.

  Returns:
    `TileLayout`.
  """
  tile_size, chunk = settings.tile_size, settings.chunk_size
  tiles_x, tiles_y = tile_grid(width, height, tile_size)
  num_tiles = tiles_x * tiles_y
  max_chunks = settings.max_chunks
  max_pairs = settings.max_intersections

  means2d, extents, depths, valid = jax.lax.stop_gradient(
      (projected.means2d, projected.extents, projected.depths, projected.valid))
  x0, x1, y0, y1 = tile_bounds(means2d, extents, width, height, tile_size)
  span_x = jnp.maximum(x1 - x0, 0)
  counts = jnp.where(valid, span_x * jnp.maximum(y1 - y0, 0), 0)

  # Front to back: pairs are emitted in depth order, so a stable sort by tile keeps it.
  order = jnp.argsort(jnp.where(valid, depths, jnp.inf), stable=True).astype(jnp.int32)
  counts_sorted = counts[order]
  ends = jnp.cumsum(counts_sorted)
  num_pairs = ends[-1]

  slot = jnp.arange(max_pairs, dtype=jnp.int32)
  search = functools.partial(jnp.searchsorted, method=settings.searchsorted_method)
  rank = search(ends, slot, side="right").astype(jnp.int32)
  rank = jnp.minimum(rank, order.shape[0] - 1)
  gid = order[rank]
  local = slot - (ends[rank] - counts_sorted[rank])
  width_g = jnp.maximum(span_x[gid], 1)
  tile = (y0[gid] + local // width_g) * tiles_x + x0[gid] + local % width_g
  tile = jnp.where(slot < num_pairs, tile, num_tiles)  # unused slots sort last
  tile_sorted, rank_sorted = _sort_by_tile_then_rank(tile, rank, num_tiles, order.shape[0])
  gid_sorted = order[rank_sorted]

  # Per-tile ranges in the sorted list, and their chunk counts after padding.
  boundaries = search(tile_sorted, jnp.arange(num_tiles + 1, dtype=jnp.int32),
                      side="left").astype(jnp.int32)
  tile_start = boundaries[:-1]
  tile_count = boundaries[1:] - tile_start
  tile_chunks = -(-tile_count // chunk)
  chunk_ends = jnp.cumsum(tile_chunks)
  num_chunks = chunk_ends[-1]

  b = jnp.arange(max_chunks, dtype=jnp.int32)
  chunk_tile = search(chunk_ends, b, side="right").astype(jnp.int32)
  in_use = chunk_tile < num_tiles
  t = jnp.minimum(chunk_tile, num_tiles - 1)
  first = (b - (chunk_ends[t] - tile_chunks[t])) * chunk  # position within the tile
  pos = first[:, None] + jnp.arange(chunk, dtype=jnp.int32)[None, :]
  live = in_use[:, None] & (pos < tile_count[t][:, None])
  index = jnp.clip(tile_start[t][:, None] + pos, 0, max_pairs - 1)
  gaussian_ids = jnp.where(live, gid_sorted[index], 0)

  # When the pair list itself was cut, the padded need is unknown; report an upper bound
  # (every tile padded by chunk - 1) so that one budget increase suffices.
  pairs_cut = num_pairs > max_pairs
  num_padded = jnp.where(pairs_cut, num_pairs + num_tiles * (chunk - 1), num_chunks * chunk)
  stats = TileStats(
      num_intersections=num_pairs.astype(jnp.int32),
      num_padded=num_padded.astype(jnp.int32),
      max_tile_load=jnp.max(tile_count).astype(jnp.int32),
      overflow=pairs_cut | (num_chunks * chunk > max_pairs),
  )
  return TileLayout(gaussian_ids, live, jnp.where(in_use, chunk_tile, num_tiles),
                    num_chunks.astype(jnp.int32), stats)


def _sort_by_tile_then_rank(tile, rank, num_tiles, num_gaussians):
  """Sorts pairs by tile, then by depth rank: each tile's list in front-to-back order.

  When both fit, they are packed into one int32 key (tile * N + rank, unique per pair):
  XLA sorts one int32 array several times faster on a CPU than it stably sorts the two
  arrays, and the renderer sorts its whole budget every call.
  """
  if (num_tiles + 1) * num_gaussians <= jnp.iinfo(jnp.int32).max:
    key = jnp.sort(tile * num_gaussians + rank)
    return key // num_gaussians, key % num_gaussians
  return jax.lax.sort((tile, rank), num_keys=1, is_stable=True)
