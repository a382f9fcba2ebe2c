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
from mfsample.model import Model, check_model, sample
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
  samples, NaN); when on the host, or a JAX array with `sync`, every entry finite and in
  [-1, 1] (`samplers.Z_RANGE`; ValueError naming the sample). A NaN row makes every Gaussian
  of that sample non-finite, the renderer culls them and U would come out finite and wrong;
  a z of 3 scales U by 9. Traced, `inputs_ok` makes the jitted functions' U NaN instead."""
  want = samplers.z_shape(model)
  got = tuple(np.shape(z))
  if len(got) != 1 + len(want) or got[1:] != want or got[0] < 1:
    raise ValueError(f"z must have shape [M >= 1, {', '.join(map(str, want))}] (M samples for "
                     f"the {model.spec.kind} sampler, e.g. sample_z(model, 2)), got "
                     f"{list(got)}")
  arg_checks.check_real_dtype("z", z)
  if arg_checks.is_traced(z) or (isinstance(z, jax.Array) and not sync):
    return
  if isinstance(z, jax.Array) and arg_checks.concrete_bool(_z_ok, z):
    return
  arg_checks.check_finite("z", np.asarray(z), axis_name="sample")
  values = np.asarray(z, np.float64).reshape(got[0], -1)
  outside = np.any((values < samplers.Z_RANGE[0]) | (values > samplers.Z_RANGE[1]), axis=1)
  if np.any(outside):
    i = int(np.argmax(outside))
    raise ValueError(f"z[{i}] (sample {i}) is outside [{samplers.Z_RANGE[0]:g}, "
                     f"{samplers.Z_RANGE[1]:g}] (max |z| = {float(np.max(np.abs(values[i]))):g}; "
                     f"{int(outside.sum())} of {got[0]} samples): z ~ U[-1, 1], as "
                     "sample_z draws it")


_z_ok = jax.jit(samplers.z_in_range)


def check_background(background, channels=3, sync=False):
  """A background colour: [channels] floats (always: an integer colour, uint8 say, is on
  another scale); in [0, 1] when on the host, or a JAX array with `sync` (ValueError naming
  the channel). Traced, `inputs_ok` makes the jitted functions' answer NaN instead."""
  if background is None:
    return
  arg_checks.check_shape("background", background, (channels,), "one colour")
  arg_checks.check_float_dtype("background", background,
                               "floats in [0, 1] (for 8-bit colours pass background / 255)")
  if arg_checks.is_traced(background) or (isinstance(background, jax.Array) and not sync):
    return
  if isinstance(background, jax.Array) and arg_checks.concrete_bool(_background_ok,
                                                                    background):
    return
  arg_checks.check_finite("background", np.asarray(background))
  values = np.asarray(background, np.float64)
  outside = (values < 0.0) | (values > 1.0)
  if np.any(outside):
    i = int(np.argmax(outside))
    raise ValueError(f"background[{i}] = {values[i]:g} is outside [0, 1] (a colour; for 8-bit "
                     "colours pass background / 255)")


def background_ok(background):
  """Scalar bool (jnp): every channel of the colour `background` lies in [0, 1]."""
  return jnp.all((background >= 0.0) & (background <= 1.0))


_background_ok = jax.jit(background_ok)


def check_inputs(model, z, background=None, *, sync=False):
  """The checks of every function of U's family (`uncertainty`, `score_cameras`, the view and
  light optimisers, `light_gram`, ...): the model (`mfsample.model.check_model`), z
  (`check_z`) and the background colour (`check_background`), all by one rule: concrete
  values (on the host, or on the device with `sync`) raise naming the argument; traced ones
  make the answer NaN (`inputs_ok`)."""
  check_model(model, sync=sync)
  check_z(model, z, sync=sync)
  check_background(background, sync=sync)


def inputs_ok(model, z, background=None):
  """Scalar bool (jnp, usable under jit): the values `check_inputs` checks are valid. The
  jitted part of each function makes its answer NaN where it is False
  (`arg_checks.nan_unless`), so a value that could not raise gives NaN, never a finite U."""
  ok = model.valid & samplers.z_in_range(z)
  return ok if background is None else ok & background_ok(background)


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
    `Uncertainty`; U and the map are NaN when the model is not valid (`Model.valid`: a
    non-finite parameter, B_hat above its bound), z holds a value outside [-1, 1] (or NaN),
    or the background one outside [0, 1]. It does not synchronise, so only host values
    raise (a numpy z or background: `ValueError` naming the sample or channel);
    `model.validate()` names what is wrong with a model.
  """
  check_inputs(model, z, background)
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
  ok = inputs_ok(model, z, background)
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
  ok = inputs_ok(model, z, background)  # (traced values cannot raise: NaN, never finite)
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

  Raises:
    ValueError: an argument out of its range, named: it synchronises anyway, so a model,
      z or background on the device is checked too (`check_inputs`).
  """
  if not isinstance(cameras, Camera) or len(cameras.batch_shape) != 1:
    raise ValueError("score_cameras takes a Camera batched over one axis [B], got "
                     + (f"batch shape {cameras.batch_shape}" if isinstance(cameras, Camera)
                        else type(cameras).__name__))
  check_inputs(model, z, background, sync=True)
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
