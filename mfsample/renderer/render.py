"""`render`: chains projection -> colour -> tile intersection -> compositing."""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp

from mfsample import arg_checks
from mfsample.camera import Camera
from mfsample.gaussians import Gaussians
from mfsample.renderer import sh as sh_lib
from mfsample.renderer.composite import composite
from mfsample.renderer.composite_pallas import composite_pallas
from mfsample.renderer.projection import project_gaussians, view_directions
from mfsample.renderer.settings import RenderSettings
from mfsample.renderer.tiles import TileStats, intersect_tiles


class RenderOutput(NamedTuple):
  """What `render` returns.

  Attributes:
    rgb: [H, W, C] blended colour over the background (C = 3, or F when `features` is given).
    alpha: [H, W] accumulated opacity, 1 - final transmittance.
    depth: [H, W] alpha-weighted camera z-depth, sum_i w_i z_i, *not* normalised by alpha:
      it fades to 0 where alpha does. `expected_depth()` divides it out.
    stats: `TileStats` (intersections, busiest tile, overflow flag).
    radii: [N] screen-space radius in pixels of each Gaussian's footprint (0 when culled;
      no gradient). Training prunes Gaussians that grow too large on screen.
    visible: [N] bool, projected in front of the near plane, on screen and live.
  """

  rgb: chex.Array
  alpha: chex.Array
  depth: chex.Array
  stats: TileStats
  radii: chex.Array
  visible: chex.Array

  def expected_depth(self, eps=1e-6):
    """[H, W] depth / alpha: the mean z of what was hit (0 where alpha <= eps)."""
    ok = self.alpha > eps
    return jnp.where(ok, self.depth / jnp.where(ok, self.alpha, 1.0), 0.0)


@functools.partial(jax.jit, static_argnames=("settings",))
def render(gaussians: Gaussians, camera: Camera, *, background=None,
           settings: RenderSettings = RenderSettings(), features=None,
           screen_offset=None) -> RenderOutput:
  """Renders Gaussians into one camera with the tile-based 3DGS rasteriser.

  Differentiable w.r.t. every array in `gaussians`, `camera` (pose and intrinsics),
  `background` and `features`. It is jitted with `settings` static (hashable), so a call
  outside `jax.jit` is compiled too and is inlined inside one; vmap it over a batched
  `Camera` or a batched `Gaussians` (leading axis on every leaf).

  A Gaussian contributes at a pixel where its alpha is >= `settings.alpha_min`, within
  `settings.radius_sigma` standard deviations (`RenderSettings` states the rule).

  Robustness: a Gaussian that is masked out, or has any non-finite parameter (mean, scale,
  quaternion, opacity, SH coefficient, or its row of `features` or `screen_offset`), is
  culled: it contributes exactly nothing, cannot turn other pixels into NaN, has
  `visible` False and radius 0, and receives zero gradients (not NaN).

  Args:
    gaussians: `Gaussians` with N >= 0 entries (unbatched).
    camera: an unbatched `Camera`.
    background: [C] floats behind the Gaussians (default: zeros): an RGB colour in [0, 1]
      (outside it `rgb` is NaN), or any values with `features`. An integer array (uint8
      0..255) is refused (`ValueError`; pass background / 255); Python numbers are floats.
    settings: `RenderSettings` (static).
    features: optional [N, F] per-Gaussian values blended instead of the SH colour
      (uncertainty maps, relighting). The output `rgb` then has F channels and no clamping.
    screen_offset: optional [N, 2] pixel offset added to the projected 2D centres. Pass
      zeros and differentiate w.r.t. it to get the loss gradient w.r.t. the screen-space
      centres, which 3DGS densification thresholds (Kerbl et al. 2023, Sec. 5.2).

  Returns:
    `RenderOutput`; all NaN for an invalid camera (`Camera.valid` is False).
  """
  if not isinstance(camera, Camera):
    raise TypeError(f"camera must be a mfsample.Camera, got {type(camera).__name__}")
  if camera.batch_shape:
    raise ValueError(f"render takes one camera; got a batch {camera.batch_shape}. "
                     "Use jax.vmap over the camera for batches.")
  # An invalid camera (`Camera.valid`: non-finite or non-rigid pose, fx or fy <= 0) cannot
  # raise under jit: its images are NaN, which every finiteness check downstream catches.
  nan_if_invalid = jnp.where(camera.valid, 0.0, jnp.nan)
  gaussians.validate()
  dtype = gaussians.means.dtype
  n = gaussians.num_gaussians
  if features is not None:
    features = jnp.asarray(features)
    if features.ndim != 2 or features.shape[0] != n:
      raise ValueError(f"features must have shape [N={n}, F], got {features.shape}")
    if not jnp.issubdtype(features.dtype, jnp.floating):
      raise ValueError(f"features must be floating point, got {features.dtype}")
  if screen_offset is not None:
    screen_offset = jnp.asarray(screen_offset)
    if screen_offset.shape != (n, 2):
      raise ValueError(f"screen_offset must have shape [N={n}, 2], got "
                       f"{list(screen_offset.shape)}")
  if n == 0:  # one masked placeholder keeps every array non-empty
    gaussians = Gaussians.empty(1, gaussians.sh_degree, dtype)
    if features is not None:
      features = jnp.zeros((1, features.shape[1]), features.dtype)
    if screen_offset is not None:
      screen_offset = jnp.zeros((1, 2), dtype)

  finite = _finite_rows(gaussians, features, screen_offset)
  gaussians, features, screen_offset = _cull_non_finite(finite, gaussians, features,
                                                        screen_offset)
  proj = project_gaussians(gaussians.means, gaussians.scales, gaussians.quats,
                           gaussians.opacities, gaussians.mask, camera, settings)
  if features is None:
    dirs = view_directions(gaussians.means, camera)
    colors = sh_lib.sh_to_color(gaussians.sh, dirs)
  else:
    colors = features.astype(dtype)
  num_channels = colors.shape[-1]
  if background is None:
    background = jnp.zeros((num_channels,), dtype)
  # Dtypes are static: an integer colour (uint8 0..255) is refused even under jit.
  arg_checks.check_float_dtype("background", background,
                               "floats (a colour in [0, 1]; for 8-bit colours pass "
                               "background / 255)")
  background = jnp.asarray(background, dtype)
  if background.shape != (num_channels,):
    raise ValueError(f"background must have shape [{num_channels}] (one value per channel of "
                     f"{'features' if features is not None else 'the RGB colour'}), got "
                     f"{list(background.shape)}")
  nan_unless_colour = nan_if_invalid
  if features is None:  # an RGB background is a colour: NaN images outside [0, 1]
    colour_ok = jnp.all((background >= 0.0) & (background <= 1.0))
    nan_unless_colour = jnp.where(camera.valid & colour_ok, 0.0, jnp.nan)

  means2d = proj.means2d
  if screen_offset is not None:
    means2d = means2d + jnp.where(proj.valid[:, None], screen_offset.astype(dtype), 0.0)
  layout = intersect_tiles(proj, camera.width, camera.height, settings)
  blend_in = jnp.concatenate([colors, proj.depths[:, None]], axis=-1)
  opacities = jnp.where(proj.valid, gaussians.opacities, 0.0)
  composite_fn = composite_pallas if settings.compositor == "pallas" else composite
  blended, alpha = composite_fn(layout, means2d, proj.conics, opacities, blend_in,
                                camera.width, camera.height, settings)
  rgb = blended[..., :num_channels] + (1.0 - alpha)[..., None] * background
  return RenderOutput(rgb=rgb + nan_unless_colour, alpha=alpha + nan_if_invalid,
                      depth=blended[..., num_channels] + nan_if_invalid,
                      stats=layout.stats, radii=proj.radii[:n], visible=proj.valid[:n])


def _finite_rows(gaussians, features, screen_offset):
  """[N] bool: every parameter of the Gaussian (and its optional rows) is finite."""
  def rows(x):
    return jnp.all(jnp.isfinite(x).reshape(x.shape[0], -1), axis=-1)

  arrays = [gaussians.means, gaussians.scales, gaussians.quats, gaussians.opacities,
            gaussians.sh]
  arrays += [x for x in (features, screen_offset) if x is not None]
  return functools.reduce(jnp.logical_and, [rows(x) for x in arrays])


def _cull_non_finite(finite, gaussians, features, screen_offset):
  """Replaces non-finite rows by a masked placeholder Gaussian (before any arithmetic).

  A select on the inputs, not a mask applied later: downstream arithmetic never sees the
  non-finite values, so nothing computes NaN * 0, and the cotangent of a replaced row is 0.
  """
  placeholder = Gaussians.empty(1, gaussians.sh_degree, gaussians.means.dtype)

  def clean(x, safe):
    keep = finite.reshape((-1,) + (1,) * (x.ndim - 1))
    return jnp.where(keep, x, safe.astype(x.dtype))

  mask = finite if gaussians.mask is None else gaussians.mask & finite
  gaussians = Gaussians(
      means=clean(gaussians.means, placeholder.means),
      scales=clean(gaussians.scales, placeholder.scales),
      quats=clean(gaussians.quats, placeholder.quats),
      opacities=clean(gaussians.opacities, placeholder.opacities),
      sh=clean(gaussians.sh, placeholder.sh),
      mask=mask)
  if features is not None:
    features = clean(features, jnp.zeros((), features.dtype))
  if screen_offset is not None:
    screen_offset = clean(screen_offset, jnp.zeros((), screen_offset.dtype))
  return gaussians, features, screen_offset
