"""Stage 3: front-to-back alpha compositing of the chunked tile lists (3DGS rules).

For pixel p and the depth-ordered Gaussians i of its tile (3DGS, Kerbl et al. 2023, Eq. 3),
with o_i the opacity, d_i(p) the Mahalanobis distance of p from the projected centre and
f_i the blended features::

  alpha_i = min(alpha_max, o_i exp(-d_i(p)^2 / 2)),  skipped (alpha_i = 0) where
            d_i(p) > r(o_i) = min(radius_sigma, sqrt(2 ln(o_i / alpha_min))),
            i.e. where alpha_i < alpha_min or d_i(p) > radius_sigma,
  T_i     = prod_{j < i} (1 - alpha_j),
  C(p)    = sum_i alpha_i T_i f_i, stopping before the first i with T_i (1 - alpha_i) < T_min.

The tile lists hold each Gaussian in every tile its footprint of radius r(o) sqrt(lambda_max)
pixels touches (`projection.py`), so every pixel where the rule lets it contribute sees it.

Padding slots of the lists and Gaussians culled before (masked, behind the camera,
non-finite) contribute exactly nothing: the values gathered into padding slots are zeros,
whatever the Gaussian slot they point at holds (a NaN included).

Transmittance is accumulated in log space. Within a chunk of C Gaussians the exclusive
prefix sum of log(1 - alpha) is one small matrix product with a strictly lower-triangular
matrix; chunks of the same tile are chained within a step by a second such product, and
across steps by a carry. The weighted sums of features are a batched matrix product too, so
the inner loop is dense linear algebra on [C, tile_size^2] blocks. The products run in full
float32 (`precision.py`).

The loop runs over steps of `chunks_per_step` chunks; each step is rematerialised in the
backward pass (`jax.checkpoint`), so memory stays bounded by one step. With
`settings.skip_unused_steps` (the default), steps past the last used chunk are skipped
(`lax.cond`), so an over-provisioned budget costs little on a CPU. On a GPU the branch of
a `lax.cond` is chosen by the host, which waits for the predicate each step (forward and
backward); without it every step runs, wasting the work of the unused budget but never
synchronising, and the loop is a fixed-trip scan.
"""

import math
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
from jax.custom_batching import custom_vmap

from mfsample.renderer.precision import MATMUL
from mfsample.renderer.tiles import TileLayout, tile_grid


class _ChunkInputs(NamedTuple):
  means2d: chex.Array  # [S, G, C, 2]
  conics: chex.Array  # [S, G, C, 3]
  opacities: chex.Array  # [S, G, C]
  features: chex.Array  # [S, G, C, F]
  live: chex.Array  # [S, G, C]
  tile: chex.Array  # [S, G]


def composite(layout: TileLayout, means2d, conics, opacities, features, width, height,
              settings):
  """Blends per-Gaussian features into an image.

  Args:
    layout: `TileLayout` from `intersect_tiles`.
    means2d: [N, 2] pixel coordinates.
    conics: [N, 3] inverse 2D covariances (a, b, c).
    opacities: [N].
    features: [N, F] values to blend (colour, depth, anything).
    width, height: image size (static).
    settings: `RenderSettings`.

  Returns:
    (image [H, W, F] = sum_i w_i f_i, alpha [H, W] = sum_i w_i).
  """
  ts, chunk, steps_g = settings.tile_size, settings.chunk_size, settings.chunks_per_step
  tiles_x, tiles_y = tile_grid(width, height, ts)
  num_tiles = tiles_x * tiles_y
  num_steps = settings.max_chunks // steps_g
  dtype = features.dtype

  def per_chunk(x):  # [N, ...] -> [S, G, C, ...]
    return chunk_values(layout, x).reshape((num_steps, steps_g, chunk) + x.shape[1:])

  xs = _ChunkInputs(
      means2d=per_chunk(means2d),
      conics=per_chunk(conics),
      opacities=per_chunk(opacities),
      features=per_chunk(features),
      live=layout.live.reshape(num_steps, steps_g, chunk),
      tile=layout.chunk_tile.reshape(num_steps, steps_g),
  )
  step_ids = jnp.arange(num_steps, dtype=jnp.int32)

  # Pixel centres of a tile, relative to its corner: [P] with P = ts * ts.
  local = jnp.arange(ts * ts, dtype=jnp.int32)
  local_x = (local % ts).astype(dtype) + 0.5
  local_y = (local // ts).astype(dtype) + 0.5
  strict_upper_c = jnp.triu(jnp.ones((chunk, chunk), dtype), k=1)  # [d, c] = 1 if d < c
  strict_lower_g = jnp.tril(jnp.ones((steps_g, steps_g), bool), k=-1)
  log_t_min = math.log(settings.transmittance_min)
  cut = -0.5 * settings.radius_sigma ** 2

  def blend_step(carry, x: _ChunkInputs):
    # Arrays are pixel-major, [G, P, C]: the prefix sum and the feature sum then contract
    # the minor axis, which measured 2x faster on CPU than [G, C, P].
    prev_tile, prev_log_t = carry
    tile = x.tile  # [G]
    origin_x = ((tile % tiles_x) * ts).astype(dtype)
    origin_y = ((tile // tiles_x) * ts).astype(dtype)
    dx = (origin_x[:, None] + local_x)[:, :, None] - x.means2d[:, None, :, 0]  # [G, P, C]
    dy = (origin_y[:, None] + local_y)[:, :, None] - x.means2d[:, None, :, 1]
    ca, cb, cc = (x.conics[:, None, :, k] for k in range(3))
    power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
    alpha = jnp.minimum(settings.alpha_max, x.opacities[:, None, :] * jnp.exp(power))
    # d <= r(o): the alpha test is d <= sqrt(2 ln(o / alpha_min)), the power test the cap.
    keep = x.live[:, None, :] & (power >= cut) & (alpha >= settings.alpha_min)
    alpha = jnp.where(keep, alpha, 0.0)
    log_keep = jnp.log1p(-alpha)  # >= log(1 - alpha_max): finite

    # log T before each Gaussian = carry + earlier chunks of the tile + earlier in chunk.
    within = jnp.matmul(log_keep, strict_upper_c, precision=MATMUL)  # [G, P, C]
    chunk_total = jnp.sum(log_keep, axis=-1)  # [G, P]
    same_tile = strict_lower_g & (tile[:, None] == tile[None, :])
    before_chunk = jnp.matmul(jnp.where(same_tile, 1.0, 0.0).astype(dtype), chunk_total,
                              precision=MATMUL)
    before_chunk += jnp.where((tile == prev_tile)[:, None], prev_log_t[None, :], 0.0)
    log_t = before_chunk[:, :, None] + within

    include = log_t + log_keep >= log_t_min
    weight = jnp.where(include, alpha * jnp.exp(log_t), 0.0)
    blended = jnp.einsum("gpc,gcf->gpf", weight, x.features, precision=MATMUL)  # [G, P, F]
    coverage = jnp.sum(weight, axis=-1)  # [G, P]
    new_carry = (tile[-1], before_chunk[-1] + chunk_total[-1])
    return new_carry, (blended, coverage)

  blend_step = jax.checkpoint(blend_step)

  def maybe_blend(carry, inputs):
    step, x = inputs

    def skip(carry, x):
      del x
      p = ts * ts
      return carry, (jnp.zeros((steps_g, p, features.shape[-1]), dtype),
                     jnp.zeros((steps_g, p), dtype))

    return jax.lax.cond(step * steps_g < chunks_in_use, blend_step, skip, carry, x)

  if settings.skip_unused_steps:
    # Under vmap (M samples, many cameras) the skip test must stay a real branch, not a
    # select that computes every step: it uses the largest chunk count in the batch.
    chunks_in_use = _max_over_batch(layout.num_chunks)
    body = maybe_blend
  else:
    body = lambda carry, inputs: blend_step(carry, inputs[1])
  init = (jnp.int32(-1), jnp.zeros((ts * ts,), dtype))
  _, (blended, coverage) = jax.lax.scan(body, init, (step_ids, xs))

  # Chunks -> tiles (unused chunks carry tile id num_tiles and land in a dropped row).
  chunk_tile = layout.chunk_tile
  p = ts * ts
  blended = jax.ops.segment_sum(blended.reshape(-1, p, features.shape[-1]), chunk_tile,
                                num_segments=num_tiles + 1, indices_are_sorted=True)
  coverage = jax.ops.segment_sum(coverage.reshape(-1, p), chunk_tile,
                                 num_segments=num_tiles + 1, indices_are_sorted=True)
  image = tiles_to_image(blended[:num_tiles], tiles_x, tiles_y, ts, width, height)
  alpha = tiles_to_image(coverage[:num_tiles, :, None], tiles_x, tiles_y, ts, width, height)
  return image, alpha[..., 0]


def chunk_values(layout: TileLayout, x):
  """Per-Gaussian values [N, ...] -> per list slot [B, C, ...], exactly 0 on padding.

  Padding slots point at Gaussian 0; a select, not a product with the mask, keeps whatever
  Gaussian 0 holds (a NaN of a masked-out Gaussian) out of them, and its cotangent is 0.
  """
  live = layout.live.reshape(layout.live.shape + (1,) * (x.ndim - 1))
  return jnp.where(live, x[layout.gaussian_ids], jnp.zeros((), x.dtype))


@custom_vmap
def _max_over_batch(n):
  """Identity on one value; under `jax.vmap`, the maximum over the batch, unbatched.

  This keeps `lax.cond` a true branch when `render` is vmapped: a batched predicate would
  turn it into a select that evaluates (and wastes) every step of the loop.
  """
  return n


@_max_over_batch.def_vmap
def _max_over_batch_rule(axis_size, in_batched, n):
  del axis_size, in_batched
  return jnp.max(n), False


def tiles_to_image(tiles, tiles_x, tiles_y, ts, width, height):
  """[T, ts*ts, F] per-tile pixels -> [H, W, F]."""
  f = tiles.shape[-1]
  img = tiles.reshape(tiles_y, tiles_x, ts, ts, f).transpose(0, 2, 1, 3, 4)
  return img.reshape(tiles_y * ts, tiles_x * ts, f)[:height, :width]
