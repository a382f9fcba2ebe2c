"""Differentiable uncertainty of a stochastic Gaussian field (paper Eq. 10-11).

For a camera and M samples theta(z_1) .. theta(z_M) of the field (`mfsample.samplers`),

  U = sum over pixels p of (1/M) sum_m || C_m(p) - C_mean(p) ||^2,
  C_mean(p) = (1/M) sum_m C_m(p),                                          (Eq. 10, 11)

the biased (1/M) sample variance of the rendered colour, summed over RGB and pixels. The
per-pixel term is the uncertainty image. U needs only forward renders, so it is
differentiable w.r.t. the camera (pose and intrinsics) through the renderer. The paper uses
M = 2 scrambled Sobol points (nearly antithetic) for optimisation; more for selection is a
config choice. A deterministic model renders M identical images: U = 0 exactly.

Batches of candidate cameras are scored by `score_cameras`: `jax.lax.map` over chunks of
cameras (memory bounded by one chunk of M renders) and, with several devices, a
`jax.shard_map` that splits the cameras over them (`mfsample.sharding`).
"""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks, samplers
from mfsample.camera import Camera
from mfsample.model import Model, sample
from mfsample.renderer import TileStats, render
from mfsample.renderer.budget import render_with_budget
from mfsample.renderer.settings import RenderSettings
from mfsample.sharding import default_num_devices, map_cameras, map_sharded


class Uncertainty(NamedTuple):
  """U of one camera.

  Attributes:
    value: scalar U (Eq. 10), summed over pixels and RGB.
    pixel_map: [H, W] per-pixel variance over the samples, summed over RGB.
    rgb_mean: [H, W, 3] mean render over the samples.
    stats: `TileStats` with a leading [M] axis (check `overflow`).
  """

  value: chex.Array
  pixel_map: chex.Array
  rgb_mean: chex.Array
  stats: TileStats


def pixel_variance(rgbs):
  """[M, H, W, C] renders -> [H, W]: (1/M) sum_m ||C_m - C_mean||^2 per pixel (Eq. 10)."""
  if np.ndim(rgbs) != 4 or np.shape(rgbs)[0] < 1:  # M = 0 would be a mean over nothing: NaN
    raise ValueError(f"rgbs must have shape [M >= 1, H, W, C], got {list(np.shape(rgbs))}")
  mean = jnp.mean(rgbs, axis=0, keepdims=True)
  return jnp.mean(jnp.sum(jnp.square(rgbs - mean), axis=-1), axis=0)


def sample_gaussians(model, z):
  """`Gaussians` of the M realisations theta(z_m), stacked on a leading [M] axis.

  Args:
    model: a `mfsample.model.Model`.
    z: `[M, *samplers.z_shape(model)]`.
  """
  return jax.vmap(lambda zi: sample(model, zi))(z)


def uncertainty_of_samples(gaussians_m, camera: Camera, *, settings: RenderSettings,
                           background, num_devices=1) -> Uncertainty:
  """U of `camera` for M sampled `Gaussians` (leading [M] axis on every leaf).

  The samples are rendered one after another (`lax.map`): unvmapped, each render skips the
  unused part of its intersection budget, and memory holds one render at a time. With
  `num_devices` > 1 they are split over the devices instead (`map_sharded`).
  """
  def one(g):
    out = render(g, camera, background=background, settings=settings)
    return out.rgb, out.stats

  rgbs, stats = map_sharded(one, gaussians_m, num_devices=num_devices)
  pmap = pixel_variance(rgbs)
  return Uncertainty(value=jnp.sum(pmap), pixel_map=pmap, rgb_mean=jnp.mean(rgbs, axis=0),
                     stats=stats)


def check_z(model, z, sync=False):
  """Checks z for U: shape `[M >= 1, *z_shape(model)]` always (M = 0 would be a mean over no
  samples, NaN); finite when on the host, or a JAX array with `sync` (a NaN row makes every
  Gaussian of that sample non-finite, the renderer culls them and U would come out finite
  and wrong: the jitted functions make it NaN instead)."""
  want = samplers.z_shape(model)
  got = tuple(np.shape(z))
  if len(got) != 1 + len(want) or got[1:] != want or got[0] < 1:
    raise ValueError(f"z must have shape [M >= 1, {', '.join(map(str, want))}] (M samples for "
                     f"the {model.spec.kind} sampler, e.g. sample_z(model, 2)), got "
                     f"{list(got)}")
  arg_checks.check_finite("z", z, axis_name="sample", sync=sync)


def check_background(background, channels=3):
  """A concrete background must be [channels] finite numbers (traced ones: shape only)."""
  if background is None:
    return
  arg_checks.check_shape("background", background, (channels,), "one colour")
  arg_checks.check_finite("background", background)


def uncertainty(model: Model, camera: Camera, z: jax.Array, *,
                settings: RenderSettings = RenderSettings(),
                background: jax.Array | None = None, num_devices: int = 1) -> Uncertainty:
  """U of a stochastic model seen from one camera (Eq. 10), and its per-pixel map.

  Differentiable w.r.t. the camera (and the model): e.g.
  `jax.grad(lambda c: uncertainty(model, c, z, settings=s).value)(camera)`.

  Args:
    model: `mfsample.model.Model` (any sampler kind; deterministic gives U = 0).
    camera: one unbatched `Camera`.
    z: `[M, *samplers.z_shape(model)]` samples, e.g. `sample_z(model, 2)`.
    settings: `RenderSettings` (static). Check `stats.overflow`: an overflowing render is
      incomplete; grow the budget (`mfsample.renderer.budget.fit_budget`) and call again.
    background: [3] colour behind the Gaussians (default black).
    num_devices: devices to split the M samples over (static).

  Returns:
    `Uncertainty`; U and the map are NaN when z holds a non-finite value (a numpy z raises
    `ValueError` naming the sample instead).
  """
  check_z(model, z)
  check_background(background)
  num_devices = arg_checks.check_int("num_devices", num_devices, minimum=1,
                                     maximum=jax.device_count())
  return _uncertainty(model, camera, z, settings=settings, background=background,
                      num_devices=num_devices)


@functools.partial(jax.jit, static_argnames=("settings", "num_devices"))
def _uncertainty(model, camera, z, *, settings, background, num_devices):
  if background is None:
    background = jnp.zeros((3,), model.params.mean["means"].dtype)
  u = uncertainty_of_samples(sample_gaussians(model, z), camera, settings=settings,
                             background=background, num_devices=num_devices)
  ok = arg_checks.all_finite(z)
  return u._replace(value=arg_checks.nan_unless(ok, u.value),
                    pixel_map=arg_checks.nan_unless(ok, u.pixel_map))


# ------------------------------------------------------------------ batches of cameras


class CameraScores(NamedTuple):
  """U of a batch of cameras.

  Attributes:
    values: [B] U per camera.
    pixel_maps: [B, H, W] per-pixel maps, or None when not requested.
    stats: `TileStats` [B, M].
  """

  values: chex.Array
  pixel_maps: chex.Array | None
  stats: TileStats


@functools.partial(jax.jit, static_argnames=("settings", "chunk_size", "num_devices",
                                             "with_maps"))
def _score(model, cameras, z, background, *, settings, chunk_size, num_devices, with_maps):
  gaussians_m = sample_gaussians(model, z)  # sampled once, shared by every camera

  def one(camera, g):
    u = uncertainty_of_samples(g, camera, settings=settings, background=background)
    return u.value, (u.pixel_map if with_maps else None), u.stats

  values, maps, stats = map_cameras(one, cameras, gaussians_m, chunk_size=chunk_size,
                                    num_devices=num_devices)
  ok = arg_checks.all_finite(z)  # (traced z cannot raise: NaN scores, never finite ones)
  values = arg_checks.nan_unless(ok, values)
  maps = None if maps is None else arg_checks.nan_unless(ok, maps)
  return CameraScores(values, maps, stats)


def score_cameras(model, cameras: Camera, z, *, settings: RenderSettings, background=None,
                  chunk_size=1, num_devices=None, with_maps=False, max_budget=1 << 24):
  """U (Eq. 10) of every camera of a batch: the candidate scorer of Ours (Sel.).

  Grows the intersection budget until no render overflows (never reports a truncated
  image), like `mfsample.renderer.budget.render_with_budget`.

  Args:
    model: `mfsample.model.Model`.
    cameras: `Camera` batched over [B].
    z: `[M, *z_shape]` samples (`mfsample.samplers.sample_z`).
    settings: starting `RenderSettings`.
    background: [3] colour (default black).
    chunk_size: cameras vmapped together (see `map_cameras`).
    num_devices: devices to shard the cameras over (default: all available, at most B).
    with_maps: also return the [B, H, W] per-pixel maps.
    max_budget: refuse to grow the budget beyond this (BudgetExceededError).

  Returns:
    (`CameraScores`, the settings that sufficed).
  """
  if not isinstance(cameras, Camera) or len(cameras.batch_shape) != 1:
    raise ValueError("score_cameras takes a Camera batched over one axis [B], got "
                     + (f"batch shape {cameras.batch_shape}" if isinstance(cameras, Camera)
                        else type(cameras).__name__))
  check_z(model, z)
  check_background(background)
  chunk_size = arg_checks.check_int("chunk_size", chunk_size, minimum=1)
  max_budget = arg_checks.check_int("max_budget", max_budget, minimum=1)
  if background is None:
    background = jnp.zeros((3,), model.params.mean["means"].dtype)
  background = jnp.asarray(background, model.params.mean["means"].dtype)
  if num_devices is None:
    num_devices = default_num_devices(cameras.batch_shape[0])
  num_devices = arg_checks.check_int("num_devices", num_devices, minimum=1,
                                     maximum=jax.device_count())
  return render_with_budget(_score, settings, model, cameras, z, background,
                            chunk_size=chunk_size, num_devices=num_devices,
                            with_maps=with_maps, max_budget=max_budget, what="scoring")
