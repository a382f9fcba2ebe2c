"""Tile intersection: completeness, order, chunk layout, overflow."""

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import RenderSettings, orbit_camera
from mfsample.renderer import projection, tiles
from mfsample.renderer.tiles import tile_grid
from mfsample.testing import random_gaussians

W, H = 70, 50
project_gaussians = jax.jit(projection.project_gaussians, static_argnums=(6,))
intersect_tiles = jax.jit(tiles.intersect_tiles, static_argnums=(1, 2, 3))


def _layout(settings, num=150):
  g = random_gaussians(num, seed=3, scale_range=(0.01, 0.2))
  cam = orbit_camera(0.3, 0.4, width=W, height=H, distance=2.5, fov_x=1.0)
  proj = project_gaussians(g.means, g.scales, g.quats, g.opacities, None, cam, settings)
  return proj, intersect_tiles(proj, W, H, settings)


def _contributing_pairs(proj, settings, num=150):
  """Brute force: (tile, Gaussian) for every tile with a pixel centre where the Gaussian
  contributes by the compositor's rule (d <= radius_sigma and alpha >= alpha_min)."""
  opacities = np.asarray(random_gaussians(num, seed=3, scale_range=(0.01, 0.2)).opacities)
  tx, _ = tile_grid(W, H, settings.tile_size)
  py, px = np.mgrid[0:H, 0:W] + 0.5
  tile = (py.astype(int) // settings.tile_size) * tx + px.astype(int) // settings.tile_size
  means2d, conics, valid = map(np.asarray, (proj.means2d, proj.conics, proj.valid))
  pairs = set()
  for i in np.flatnonzero(valid):
    dx, dy = px - means2d[i, 0], py - means2d[i, 1]
    a, b, c = conics[i]
    power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
    alpha = np.minimum(settings.alpha_max, opacities[i] * np.exp(power))
    keep = (power >= -0.5 * settings.radius_sigma ** 2) & (alpha >= settings.alpha_min)
    pairs.update((int(t), int(i)) for t in np.unique(tile[keep]))
  return pairs


def test_every_overlapping_tile_is_listed_once_in_depth_order():
  settings = RenderSettings(max_intersections=4096, chunk_size=8, chunks_per_step=4)
  proj, layout = _layout(settings)
  assert not bool(layout.stats.overflow)
  ids, live = np.asarray(layout.gaussian_ids), np.asarray(layout.live)
  chunk_tile = np.asarray(layout.chunk_tile)
  listed = [(int(chunk_tile[b]), int(ids[b, c])) for b, c in np.argwhere(live)]
  assert len(listed) == len(set(listed)) == int(layout.stats.num_intersections)
  # The listed set contains every tile where the Gaussian contributes to a pixel (it may add
  # tiles its bounding box touches without a contributing pixel, which cost time only).
  assert _contributing_pairs(proj, settings) <= set(listed)
  # Chunks belong to one tile each, tiles ascending, depth ascending within a tile.
  depths = np.asarray(proj.depths)
  num_chunks = int(layout.num_chunks)
  assert np.all(np.diff(chunk_tile[:num_chunks]) >= 0)
  assert np.all(chunk_tile[num_chunks:] == tile_grid(W, H, 16)[0] * tile_grid(W, H, 16)[1])
  for t in np.unique(chunk_tile[:num_chunks]):
    rows = chunk_tile == t
    d = depths[ids[rows][live[rows]]]
    assert np.all(np.diff(d) >= 0)
    # Padding only at the end of a tile's last chunk.
    flat = live[rows].ravel()
    assert np.all(flat[: flat.sum()]) and not np.any(flat[flat.sum():])
  assert int(layout.stats.num_padded) == num_chunks * settings.chunk_size
  assert int(layout.stats.max_tile_load) == max(
      np.sum(live[chunk_tile == t]) for t in np.unique(chunk_tile[:num_chunks]))


def test_bounding_boxes_are_tighter_than_the_bounding_squares():
  """The extents are the ellipse's exact x and y extremes: never beyond its bounding disc,
  touching it along one axis, and on these anisotropic Gaussians fewer tiles in all."""
  settings = RenderSettings(max_intersections=4096, chunk_size=8, chunks_per_step=4)
  proj, layout = _layout(settings)
  radii, extents, valid = map(np.asarray, (proj.radii, proj.extents, proj.valid))
  assert np.all(extents <= radii[:, None]) and np.all(extents[~valid] == 0)
  # lambda_max <= a + c <= 2 max(a, c): the box is at least the square shrunk by sqrt(2).
  assert np.all(extents[valid].max(axis=1) >= (1 - 1e-5) * radii[valid] / np.sqrt(2))
  x0, x1, y0, y1 = map(np.asarray, tiles.tile_bounds(
      proj.means2d, jnp.stack([proj.radii] * 2, -1), W, H, settings.tile_size))
  squares = int(np.sum(np.where(valid, (x1 - x0) * (y1 - y0), 0)))
  assert int(layout.stats.num_intersections) < squares


def test_overflow_is_flagged_with_an_upper_bound_of_the_need():
  big = RenderSettings(max_intersections=4096, chunk_size=8, chunks_per_step=4)
  _, full = _layout(big)
  for budget in (32, int(full.stats.num_padded) // 64 * 32):
    _, cut = _layout(big.replace(max_intersections=budget))
    assert bool(cut.stats.overflow)
    assert int(cut.stats.num_intersections) == int(full.stats.num_intersections)
    assert int(cut.stats.num_padded) >= int(full.stats.num_padded)


def test_searchsorted_methods_give_the_same_layout():
  """`searchsorted_method` is a speed knob (GPUs may prefer "sort" or "compare_all")."""
  settings = RenderSettings(max_intersections=1024, chunk_size=8, chunks_per_step=4)
  _, want = _layout(settings, num=40)
  _, got = _layout(settings.replace(searchsorted_method="sort"), num=40)
  for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_no_valid_gaussians_gives_an_empty_layout():
  settings = RenderSettings(max_intersections=256, chunk_size=8, chunks_per_step=4)
  g = random_gaussians(10, seed=0)
  cam = orbit_camera(0.3, 0.4, width=W, height=H, distance=3.5)
  proj = project_gaussians(g.means, g.scales, g.quats, g.opacities, jnp.zeros(10, bool), cam,
                           settings)
  layout = intersect_tiles(proj, W, H, settings)
  assert int(layout.num_chunks) == 0 and not np.any(np.asarray(layout.live))
  assert int(layout.stats.num_intersections) == 0 and not bool(layout.stats.overflow)


def test_pair_sort_is_by_tile_then_rank_with_and_without_key_packing():
  rng = np.random.default_rng(0)
  rank = np.sort(rng.integers(0, 500, 3000)).astype(np.int32)  # emitted front to back
  for num_tiles in (40, 1 << 22):  # packed into one int32 key; too many tiles to pack
    tile = rng.integers(0, min(num_tiles, 1000) + 1, 3000).astype(np.int32)
    got = tiles._sort_by_tile_then_rank(jnp.asarray(tile), jnp.asarray(rank), num_tiles, 500)
    order = np.lexsort((rank, tile))
    np.testing.assert_array_equal(np.asarray(got[0]), tile[order])
    np.testing.assert_array_equal(np.asarray(got[1]), rank[order])
