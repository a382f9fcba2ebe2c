"""Stage 3 as a Pallas kernel for GPUs: one program per tile, the maths of `composite.py`.

`RenderSettings(compositor="pallas")` selects it. Projection, SH colours, the tile lists and
the gather of per-Gaussian values into list slots stay in jax.numpy (so gradients w.r.t. the
camera pose, the features and `screen_offset` flow as before); only the blend of one tile's
list is a kernel. The jnp compositor (`composite.py`) stays the CPU default and the
reference it is tested against.

Forward: program t owns tile t and loops over the tile's own chunks (a contiguous range of
the chunk list, found from `chunk_tile`), front to back, on a [tile_size^2, chunk_size]
block per chunk, with the same expressions as the jnp compositor. It stops early once every
pixel of the tile has fallen below the transmittance limit. Nothing is shared between
programs, so there is no race and no atomic.

Backward (`jax.custom_vjp`): the same program recomputes each chunk's alphas, back to front.
With G_i(p) = sum_f g_f(p) f_i,f + g_alpha(p) the cotangent of blending Gaussian i into
pixel p, w_i = alpha_i T_i its weight and S_i(p) = sum_{k > i} w_k G_k the part of the
pixel blended behind it,

  dL/df_i,f  = sum_p w_i(p) g_f(p),
  dL/dalpha_i(p) = T_i G_i - S_i / (1 - alpha_i)   (for the Gaussians the pixel blended),

and the chain rule through alpha = min(alpha_max, o exp(power)) gives the opacity, centre
and conic gradients. T_i is recovered from the pixel's final transmittance, subtracting
log(1 - alpha) going back (as 3DGS divides by 1 - alpha); S_i is a suffix sum. The forward
pass saves per pixel only the final log-transmittance and the list position just after the
last entry the pixel blended with alpha >= alpha_min (gsplat's per-pixel last index): the
entries behind it add nothing to the pixel nor to any gradient, so each tile's backward
walk starts at the largest such position over its pixels, not at the end of its list.
Each program writes the gradient rows of its own chunks ([B, 6, C] geometry, [B, F, C]
features; one owner per row, no race); jnp's gather transposes them into per-Gaussian sums.

Backend: Triton (`jax.experimental.pallas.triton`), not Mosaic GPU. The kernel is a
per-tile loop of elementwise maths, exponentials, short prefix sums and reductions over
[tile_size^2, chunk_size] register blocks, with data-dependent loop bounds: Triton's
block-level model says exactly that, and it runs on any CUDA GPU Triton supports (and ROCm).
Mosaic GPU is built around the asynchronous copies and warpgroup tensor-core products of
Hopper and later GPUs, which this kernel does not use; its lowering needs the Mosaic GPU
bindings that ship with the CUDA plugin, so on a CPU-only install it cannot even be
lowered, and no CPU test could check that the kernel compiles for CUDA. The Triton lowering
runs in Python and embeds the Triton IR in the program (XLA compiles it on the GPU), which
lets the test suite export the kernel for CUDA on a CPU. JAX 0.11 deprecates the Triton
backend; the kernel body uses only backend-neutral Pallas (ref loads and stores, `lax`
loops), so a move to Mosaic GPU's `plgpu.kernel` once Triton is removed changes the call,
not the maths.

On a CPU the same kernel runs in the Pallas interpreter (`interpret=True`), selected when the
program is lowered for the CPU (`lax.platform_dependent`), so the test suite runs the very
kernel a GPU compiles.
"""

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.experimental import pallas as pl
from jax.experimental.pallas import triton as pltriton

from mfsample.renderer.composite import chunk_values, tiles_to_image
from mfsample.renderer.tiles import TileLayout, tile_grid

# Rows of the per-slot geometry block [B, 6, C].
_MEAN_X, _MEAN_Y, _CONIC_A, _CONIC_B, _CONIC_C, _OPACITY = range(6)


class KernelParams(NamedTuple):
  """The kernels' static parameters (hashable: they are a static argument)."""

  tile_size: int
  tiles_x: int
  num_tiles: int
  chunk_size: int
  width: int
  height: int
  alpha_max: float
  alpha_min: float
  log_t_min: float  # log(transmittance_min)
  cut: float  # -radius_sigma^2 / 2: the rule's cap, on the exponent
  warps: int = 0  # RenderSettings.pallas_warps; 0: automatic

  @property
  def pixels(self):
    return self.tile_size * self.tile_size

  @property
  def num_warps(self):
    # Automatic: one warp per 32 pixels of the tile (16 x 16 -> 8 warps, as CUDA 3DGS runs
    # 256 threads a tile). chunk_size sets the block's other side.
    return self.warps or max(1, min(8, self.pixels // 32))


def composite_pallas(layout: TileLayout, means2d, conics, opacities, features, width, height,
                     settings):
  """Same contract as `composite.composite`: (image [H, W, F], alpha [H, W])."""
  ts = settings.tile_size
  tiles_x, tiles_y = tile_grid(width, height, ts)
  params = KernelParams(
      tile_size=ts, tiles_x=tiles_x, num_tiles=tiles_x * tiles_y,
      chunk_size=settings.chunk_size, width=width, height=height,
      alpha_max=settings.alpha_max, alpha_min=settings.alpha_min,
      log_t_min=math.log(settings.transmittance_min),
      cut=-0.5 * settings.radius_sigma ** 2, warps=settings.pallas_warps)
  dtype = features.dtype
  geometry = jnp.concatenate([means2d, conics, opacities[:, None]], axis=-1).astype(dtype)
  geometry = jnp.swapaxes(chunk_values(layout, geometry), 1, 2)  # [B, 6, C]
  slot_features = jnp.swapaxes(chunk_values(layout, features), 1, 2)  # [B, F, C]
  first, count = tile_ranges(layout.chunk_tile, params.num_tiles, settings.searchsorted_method)
  blended, coverage = composite_tiles(params, first, count, geometry, slot_features)
  image = tiles_to_image(jnp.swapaxes(blended, 1, 2), tiles_x, tiles_y, ts, width, height)
  alpha = tiles_to_image(coverage[..., None], tiles_x, tiles_y, ts, width, height)
  return image, alpha[..., 0]


def tile_ranges(chunk_tile, num_tiles, method="scan"):
  """Each tile's chunks: (first [T], count [T]) int32, from the sorted [B] `chunk_tile`.

  Unused chunks carry tile id `num_tiles`, past every tile; a tile without chunks gets
  count 0.
  """
  tiles = jnp.arange(num_tiles, dtype=chunk_tile.dtype)
  first = jnp.searchsorted(chunk_tile, tiles, side="left", method=method)
  end = jnp.searchsorted(chunk_tile, tiles, side="right", method=method)
  return first.astype(jnp.int32), (end - first).astype(jnp.int32)


@functools.partial(jax.custom_vjp, nondiff_argnums=(0,))
def composite_tiles(params, first, count, geometry, features):
  """Blends every tile's chunks.

  Args:
    params: `KernelParams`.
    first, count: [T] int32 chunk range of each tile (`tile_ranges`).
    geometry: [B, 6, C] per list slot: mean x, mean y, conic a, b, c, opacity (0 on padding).
    features: [B, F, C] per list slot.

  Returns:
    (blended [T, F, P], coverage [T, P]), P = tile_size^2 pixels in row-major tile order.
  """
  blended, coverage, _, _ = _forward(params, first, count, geometry, features)
  return blended, coverage


def _composite_tiles_fwd(params, first, count, geometry, features):
  blended, coverage, log_t, blended_count = _forward(params, first, count, geometry, features)
  return (blended, coverage), (first, count, geometry, features, log_t, blended_count)


def _composite_tiles_bwd(params, residuals, cotangents):
  first, count, geometry, features, log_t, blended_count = residuals
  d_blended, d_coverage = cotangents
  d_geometry, d_features = _backward(params, first, count, geometry, features, log_t,
                                     blended_count, d_blended, d_coverage)
  return None, None, d_geometry, d_features


composite_tiles.defvjp(_composite_tiles_fwd, _composite_tiles_bwd)


# ----------------------------------------------------------------------------- the kernels


def _pallas(kernel, params, out_shape, args, input_output_aliases=None):
  """Calls `kernel` on a grid of one program per tile: compiled (Triton) on a GPU, in the
  Pallas interpreter when lowered for a CPU."""
  def call(*arrays, interpret):
    return pl.pallas_call(
        functools.partial(kernel, params), out_shape=out_shape, grid=(params.num_tiles,),
        input_output_aliases=input_output_aliases or {}, interpret=interpret,
        compiler_params=pltriton.CompilerParams(num_warps=params.num_warps),
        name=kernel.__name__.strip("_"))(*arrays)

  return jax.lax.platform_dependent(*args, cpu=functools.partial(call, interpret=True),
                                    default=functools.partial(call, interpret=False))


def _forward(params, first, count, geometry, features):
  t, p = params.num_tiles, params.pixels
  f = features.shape[1]
  dtype = features.dtype
  out_shape = (jax.ShapeDtypeStruct((t, f, p), dtype),  # blended features
               jax.ShapeDtypeStruct((t, p), dtype),  # coverage, sum of weights
               jax.ShapeDtypeStruct((t, p), dtype),  # log T after the last blended entry
               jax.ShapeDtypeStruct((t, p), jnp.int32))  # position after the last blended
  return _pallas(_forward_kernel, params, out_shape, (first, count, geometry, features))


def _backward(params, first, count, geometry, features, log_t, blended_count, d_blended,
              d_coverage):
  # The gradient buffers start as zeros (aliased inputs): a program writes only the chunks
  # its pixels blended, and unused chunks belong to no program.
  zeros = (jnp.zeros_like(geometry), jnp.zeros_like(features))
  out_shape = (jax.ShapeDtypeStruct(geometry.shape, geometry.dtype),
               jax.ShapeDtypeStruct(features.shape, features.dtype))
  args = (first, count, geometry, features, log_t, blended_count, d_blended, d_coverage)
  return _pallas(_backward_kernel, params, out_shape, args + zeros,
                 input_output_aliases={len(args): 0, len(args) + 1: 1})


def _pixel_centres(params, tile, dtype):
  """[P] x and y of the tile's pixel centres, and whether each lies in the image."""
  ts = params.tile_size
  local = jax.lax.broadcasted_iota(jnp.int32, (params.pixels,), 0)
  tile_row = jax.lax.div(tile, jnp.int32(params.tiles_x))
  tile_col = tile - tile_row * params.tiles_x
  ix = tile_col * ts + jax.lax.rem(local, jnp.int32(ts))
  iy = tile_row * ts + jax.lax.div(local, jnp.int32(ts))
  inside = (ix < params.width) & (iy < params.height)
  return ix.astype(dtype) + 0.5, iy.astype(dtype) + 0.5, inside


class _ChunkAlpha(NamedTuple):
  """One chunk against one tile's pixels; [P, C] arrays unless stated."""

  alpha: jax.Array  # min(alpha_max, raw) where kept, else 0
  raw: jax.Array  # o exp(power), before the clamp
  gauss: jax.Array  # exp(power)
  kept: jax.Array  # bool: d <= r(o), i.e. power >= cut and alpha >= alpha_min
  dx: jax.Array
  dy: jax.Array
  conic: tuple  # (a, b, c), each [1, C]


def _chunk_alpha(params, geometry_ref, chunk, px, py):
  """The expressions of the jnp compositor, on one chunk's [P, C] block."""
  def row(r):
    return geometry_ref[chunk, r, :][None, :]  # [1, C]

  ca, cb, cc = row(_CONIC_A), row(_CONIC_B), row(_CONIC_C)
  dx = px[:, None] - row(_MEAN_X)
  dy = py[:, None] - row(_MEAN_Y)
  power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
  gauss = jnp.exp(power)
  raw = row(_OPACITY) * gauss
  alpha = jnp.minimum(params.alpha_max, raw)
  # d <= r(o): the alpha test is d <= sqrt(2 ln(o / alpha_min)), the power test the cap.
  kept = (power >= params.cut) & (alpha >= params.alpha_min)
  alpha = jnp.where(kept, alpha, 0.0)
  return _ChunkAlpha(alpha, raw, gauss, kept, dx, dy, (ca, cb, cc))


def _exclusive_cumsum(x):
  """Sum of the entries before each one along axis 1 (Triton has no reverse or shift)."""
  return jnp.cumsum(x, axis=1) - x


def _forward_kernel(params, first_ref, count_ref, geometry_ref, features_ref,
                    blended_ref, coverage_ref, log_t_ref, blended_count_ref):
  tile = pl.program_id(0)
  slot = jax.lax.broadcasted_iota(jnp.int32, (1, params.chunk_size), 1)
  num_features = features_ref.shape[1]
  dtype = features_ref.dtype
  px, py, inside = _pixel_centres(params, tile, dtype)
  first, count = first_ref[tile], count_ref[tile]
  zeros = jnp.zeros((params.pixels,), dtype)

  def pixels_open(state):
    i, log_t_all = state[0], state[1]
    # Done once every pixel of the image in this tile is below the transmittance limit.
    brightest = jnp.max(jnp.where(inside, log_t_all, -jnp.inf))
    return (i < count) & (brightest >= params.log_t_min)

  def blend_chunk(state):
    # log_t_all sums log(1 - alpha) over every entry so far (as the jnp compositor's
    # carry); log_t_blended only over the entries the pixel blended (the residual).
    i, log_t_all, log_t_blended, last, coverage, blended = state
    chunk = first + i
    c = _chunk_alpha(params, geometry_ref, chunk, px, py)
    log_keep = jnp.log1p(-c.alpha)  # >= log(1 - alpha_max): finite
    log_t = log_t_all[:, None] + _exclusive_cumsum(log_keep)
    include = log_t + log_keep >= params.log_t_min
    weight = jnp.where(include, c.alpha * jnp.exp(log_t), 0.0)
    blended = tuple(acc + jnp.sum(weight * features_ref[chunk, k, :][None, :], axis=1)
                    for k, acc in enumerate(blended))
    return (i + 1, log_t_all + jnp.sum(log_keep, axis=1),
            log_t_blended + jnp.sum(jnp.where(include, log_keep, 0.0), axis=1),
            # Blended with alpha >= alpha_min (kept): entries not kept have alpha 0, no
            # weight and no gradient. `include` is a prefix of the list, so every entry
            # before `last` was blended.
            jnp.maximum(last, jnp.max(jnp.where(include & c.kept,
                                                (i * params.chunk_size + 1) + slot, 0),
                                      axis=1)),
            coverage + jnp.sum(weight, axis=1), blended)

  init = (jnp.int32(0), zeros, zeros, jnp.zeros((params.pixels,), jnp.int32), zeros,
          (zeros,) * num_features)
  _, _, log_t_blended, last, coverage, blended = jax.lax.while_loop(
      pixels_open, blend_chunk, init)
  for k in range(num_features):
    blended_ref[tile, k, :] = blended[k]
  coverage_ref[tile, :] = coverage
  log_t_ref[tile, :] = log_t_blended
  blended_count_ref[tile, :] = last


def _backward_kernel(params, first_ref, count_ref, geometry_ref, features_ref, log_t_ref,
                     blended_count_ref, d_blended_ref, d_coverage_ref, zeros_geometry_ref,
                     zeros_features_ref, d_geometry_ref, d_features_ref):
  del zeros_geometry_ref, zeros_features_ref  # aliased to the outputs
  tile = pl.program_id(0)
  num_features = features_ref.shape[1]
  dtype = features_ref.dtype
  chunk_size = params.chunk_size
  px, py, _ = _pixel_centres(params, tile, dtype)
  first, count = first_ref[tile], count_ref[tile]
  num_blended = blended_count_ref[tile, :]  # [P]: entries [0, n) hold all the pixel blended
  g_features = [d_blended_ref[tile, k, :][:, None] for k in range(num_features)]  # [P, 1]
  g_coverage = d_coverage_ref[tile, :][:, None]
  # Chunks past the last entry any pixel blended get no gradient (their rows stay 0): the
  # walk back starts at the chunk of the tile's largest last index.
  end = jnp.minimum(count, jax.lax.div(jnp.max(num_blended) + chunk_size - 1,
                                       jnp.int32(chunk_size)))
  slot = jax.lax.broadcasted_iota(jnp.int32, (1, chunk_size), 1)

  def unblend_chunk(j, state):
    log_t_after, behind = state  # [P]: log T after this chunk; S of the chunks behind it
    i = end - 1 - j
    chunk = first + i
    c = _chunk_alpha(params, geometry_ref, chunk, px, py)
    blended = i * chunk_size + slot < num_blended[:, None]  # [P, C]
    log_keep = jnp.where(blended, jnp.log1p(-c.alpha), 0.0)
    log_t_before = log_t_after - jnp.sum(log_keep, axis=1)
    trans = jnp.exp(log_t_before[:, None] + _exclusive_cumsum(log_keep))  # T_i
    weight = jnp.where(blended, c.alpha * trans, 0.0)
    feats = [features_ref[chunk, k, :][None, :] for k in range(num_features)]  # [1, C]
    cotangent = g_coverage + sum(g * f for g, f in zip(g_features, feats, strict=True))
    weighted = weight * cotangent
    chunk_total = jnp.sum(weighted, axis=1)
    later = behind[:, None] + (chunk_total[:, None] - jnp.cumsum(weighted, axis=1))  # S_i
    d_alpha = jnp.where(blended, trans * cotangent - later / (1.0 - c.alpha), 0.0)
    # d min(alpha_max, raw) / d raw, with jax's convention of 1/2 at a tie.
    slope = jnp.where(c.raw < params.alpha_max, 1.0,
                      jnp.where(c.raw == params.alpha_max, 0.5, 0.0))
    d_raw = jnp.where(c.kept, d_alpha * slope, 0.0)
    d_power = d_raw * c.raw
    ca, cb, cc = c.conic
    rows = {
        _MEAN_X: d_power * (ca * c.dx + cb * c.dy),
        _MEAN_Y: d_power * (cc * c.dy + cb * c.dx),
        _CONIC_A: -0.5 * d_power * c.dx * c.dx,
        _CONIC_B: -d_power * c.dx * c.dy,
        _CONIC_C: -0.5 * d_power * c.dy * c.dy,
        _OPACITY: d_raw * c.gauss,
    }
    for r, value in rows.items():
      d_geometry_ref[chunk, r, :] = jnp.sum(value, axis=0)
    for k in range(num_features):
      d_features_ref[chunk, k, :] = jnp.sum(weight * g_features[k], axis=0)
    return log_t_before, behind + chunk_total

  init = (log_t_ref[tile, :], jnp.zeros((params.pixels,), dtype))
  jax.lax.fori_loop(0, end, unblend_chunk, init)
