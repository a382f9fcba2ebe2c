"""Uncertainty over lights: U(xi) (paper Eq. 10 under the light xi) and its quadratic form Q.

For cameras c = 1..B and M samples theta(z_m) of a relightable field,

  U(xi) = sum_c sum_pixels (1/M) sum_m || C_m,c(xi) - mean_m C_m,c(xi) ||^2,      (Eq. 10)

the camera U of `mfsample.uncertainty` under the light xi, summed over the cameras. Every
sample's image is linear in xi: C_m,c(xi) = sum_b xi_b I_m,c,b with I_m,c,b its image under
the basis light e_b (compositing is linear in the radiance, and the radiance is linear in
xi). Hence

  U(xi) = xi^T Q xi,  Q_bd = sum_c sum_pixels,channels (1/M) sum_m D_m,c,b D_m,c,d,
  D_m,c,b = I_m,c,b - mean_m I_m,c,b,

Q symmetric positive semi-definite [n, n]. `light_uncertainty` renders the samples under xi
and is differentiable w.r.t. xi (the paper's route: gradient ascent through the renderer);
`light_gram` assembles Q from one render per sample and camera whose n x 3 features are
the per-coefficient radiances (`field.render_basis`). Consequences: U(c xi) = c^2 U(xi), so
lights are compared at one norm; U(e_j) = Q_jj; the best light of a given norm is Q's top
eigenvector. Cameras are mapped (`jax.lax.map`) and, with several devices, sharded
(`mfsample.sharding.map_cameras`), like candidate cameras.
"""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks, samplers
from mfsample.camera import Camera
from mfsample.lighting import field
from mfsample.lighting import lights as lights_lib
from mfsample.renderer.budget import render_with_budget
from mfsample.renderer.settings import RenderSettings
from mfsample.renderer.tiles import TileStats
from mfsample.sharding import default_num_devices, map_cameras
from mfsample.view_uncertainty import check_inputs, inputs_ok, pixel_variance


class LightUncertainty(NamedTuple):
  """U(xi) of a batch of cameras.

  Attributes:
    value: scalar U(xi), summed over the cameras.
    per_camera: [B] U of each camera.
    stats: `TileStats` [B, M] (check `overflow`).
  """

  value: chex.Array
  per_camera: chex.Array
  stats: TileStats


class LightGram(NamedTuple):
  """The quadratic form of U over lights.

  Attributes:
    q: [n, n] Q, symmetric PSD: U(xi) = xi^T Q xi.
    per_camera: [B, n, n] each camera's share.
    stats: `TileStats` [B, M].
  """

  q: chex.Array
  per_camera: chex.Array
  stats: TileStats


def sample_raw(model, z):
  """Raw groups of the M realisations theta(z_m), stacked on a leading [M] axis."""
  return jax.vmap(lambda zi: samplers.perturb(model, zi))(z)


def _check_model(model):
  return field.coefficient_counts(model)


def check_cameras(cameras):
  if not isinstance(cameras, Camera) or len(cameras.batch_shape) != 1:
    raise ValueError("cameras must be a Camera batched over one axis [B], got "
                     + (f"batch shape {cameras.batch_shape}" if isinstance(cameras, Camera)
                        else type(cameras).__name__))


def _check_xi(xi, n):
  """Shape check always; finiteness only for concrete values (not under jit or grad: there a
  non-finite light gives NaN, `_nan_unless_valid`)."""
  if isinstance(xi, jax.core.Tracer):
    if tuple(xi.shape) != (n,):
      raise ValueError(f"xi must be one SH light of {n} coefficients (shape [{n}]), got "
                       f"shape {list(xi.shape)}")
    return xi
  return jnp.asarray(lights_lib.check_light(xi, n))


def _nan_unless_valid(x, model, z, xi=None):
  """x, or NaN unless the model, z (`mfsample.view_uncertainty.inputs_ok`) and the light are
  valid. A NaN light (or z, or Gaussian) makes radiances non-finite; the renderer culls
  those Gaussians, and without this U would be finite (exactly 0 for a NaN light)."""
  ok = inputs_ok(model, z)
  if xi is not None:
    ok = ok & arg_checks.all_finite(xi)
  return arg_checks.nan_unless(ok, x)


@functools.partial(jax.jit, static_argnames=("settings", "num_devices"))
def _light_uncertainty(model, cameras, z, xi, *, settings, num_devices):
  raw_m = sample_raw(model, z)
  xi = xi.astype(model.params.mean["means"].dtype)

  def one(camera, raw_m):
    def sample(raw):
      out = field.render_relit(raw, model.mask, xi, camera, settings=settings)
      return out.rgb, out.stats

    rgbs, stats = jax.lax.map(sample, raw_m)  # one render at a time: budget skipping
    return jnp.sum(pixel_variance(rgbs)), stats

  values, stats = map_cameras(one, cameras, raw_m, num_devices=num_devices)
  values = _nan_unless_valid(values, model, z, xi)
  return LightUncertainty(jnp.sum(values), values, stats)


def light_uncertainty(model, cameras, z, xi, *, settings: RenderSettings, num_devices=1):
  """U(xi) (Eq. 10 under the light xi), summed over `cameras`; differentiable w.r.t. xi.

  E.g. `jax.grad(lambda x: light_uncertainty(model, cams, z, x, settings=s).value)(xi)`.

  Args:
    model: a relightable `mfsample.model.Model` (`field`).
    cameras: `Camera` batched over [B].
    z: `[M, *samplers.z_shape(model)]` samples (`mfsample.samplers.sample_z`).
    xi: [n] white SH light (finite; checked when concrete).
    settings: `RenderSettings` (static); check `stats.overflow`, or use
      `light_uncertainty_fitted`, which grows the budget.
    num_devices: devices to shard the cameras over (static).

  Returns:
    `LightUncertainty`; NaN where the model is not valid (`Model.valid`) or z is outside
    [-1, 1] (not synchronising, it raises only for host values, as `mfsample.uncertainty`).
  """
  _, n = _check_model(model)
  check_cameras(cameras)
  check_inputs(model, z)
  num_devices = arg_checks.check_int("num_devices", num_devices, minimum=1,
                                     maximum=jax.device_count())
  return _light_uncertainty(model, cameras, z, _check_xi(xi, n), settings=settings,
                            num_devices=num_devices)


@functools.partial(jax.jit, static_argnames=("settings",))
def light_pixel_map(model, camera, z, xi, *, settings: RenderSettings):
  """(per-pixel map [H, W], mean image [H, W, 3], `TileStats` [M]) of U(xi) at one camera:
  the variance over the M samples of the radiance under xi, summed over RGB (the uncertainty
  image of Eq. 10 under the light xi; its sum is that camera's share of U(xi))."""
  _, n = _check_model(model)
  check_inputs(model, z)
  xi = _check_xi(xi, n).astype(model.params.mean["means"].dtype)

  def sample(raw):
    out = field.render_relit(raw, model.mask, xi, camera, settings=settings)
    return out.rgb, out.stats

  rgbs, stats = jax.lax.map(sample, sample_raw(model, z))
  return (_nan_unless_valid(pixel_variance(rgbs), model, z, xi),
          _nan_unless_valid(jnp.mean(rgbs, axis=0), model, z, xi), stats)


def light_uncertainty_fitted(model, cameras, z, xi, *, settings: RenderSettings,
                             max_budget=1 << 24):
  """(`LightUncertainty`, settings that sufficed): `light_uncertainty` with the budget grown
  until no render overflows (never a truncated image)."""
  _, n = _check_model(model)
  check_cameras(cameras)
  check_inputs(model, z, sync=True)  # it synchronises anyway
  max_budget = arg_checks.check_int("max_budget", max_budget, minimum=1)
  xi = _check_xi(xi, n)
  return render_with_budget(_light_uncertainty, settings, model, cameras, z, xi,
                            num_devices=default_num_devices(cameras.batch_shape[0]),
                            max_budget=max_budget, what="light uncertainty")


@functools.partial(jax.jit, static_argnames=("settings", "num_devices"))
def _light_gram(model, cameras, z, *, settings, num_devices):
  raw_m = sample_raw(model, z)

  def one(camera, raw_m):
    def sample(raw):
      images, out = field.render_basis(raw, model.mask, camera, settings=settings)
      return images, out.stats

    images, stats = jax.lax.map(sample, raw_m)  # [M, H, W, n, 3]
    d = images - jnp.mean(images, axis=0, keepdims=True)
    return jnp.einsum("mhwbc,mhwdc->bd", d, d) / images.shape[0], stats

  per_camera, stats = map_cameras(one, cameras, raw_m, num_devices=num_devices)
  per_camera = _nan_unless_valid(per_camera, model, z)
  q = jnp.sum(per_camera, axis=0)
  return LightGram(0.5 * (q + q.T), per_camera, stats)


def light_gram(model, cameras, z, *, settings: RenderSettings, max_budget=1 << 24,
               num_devices=None):
  """Q of U(xi) = xi^T Q xi over `cameras` (module docstring), budget grown on overflow.

  Args:
    model: a relightable `Model`.
    cameras: `Camera` [B].
    z: `[M, *z_shape]` samples.
    settings: starting `RenderSettings`.
    max_budget: refuse to grow the budget beyond this (BudgetExceededError).
    num_devices: devices to shard the cameras over (default: all, at most B).

  Returns:
    (`LightGram`, the settings that sufficed).
  """
  _check_model(model)
  check_cameras(cameras)
  check_inputs(model, z, sync=True)  # it synchronises anyway
  max_budget = arg_checks.check_int("max_budget", max_budget, minimum=1)
  if num_devices is None:
    num_devices = default_num_devices(cameras.batch_shape[0])
  num_devices = arg_checks.check_int("num_devices", num_devices, minimum=1,
                                     maximum=jax.device_count())
  return render_with_budget(_light_gram, settings, model, cameras, z, num_devices=num_devices,
                            max_budget=max_budget, what="light Gram matrix")


def check_q(q, name="q"):
  """Q as float64 [n, n]: square, finite and symmetric (relative 1e-6; `light_gram` returns it
  exactly symmetric). ValueError naming `name` otherwise: `eigh` would read one triangle of a
  non-symmetric matrix and silently ignore the other."""
  arg_checks.check_real_dtype(name, q)
  q = np.asarray(q, np.float64)
  if q.ndim != 2 or q.shape[0] != q.shape[1] or q.shape[0] < 1:
    raise ValueError(f"{name} must be a square [n, n] matrix, got shape {list(q.shape)}")
  arg_checks.check_finite(name, q)
  asym = float(np.max(np.abs(q - q.T)))
  if asym > 1e-6 * max(float(np.max(np.abs(q))), 1e-30):
    raise ValueError(f"{name} must be symmetric (U(xi) = xi^T Q xi), got max |Q - Q^T| = "
                     f"{asym:.3g}")
  return q


def quadratic_u(q, lights):
  """U of each light from Q: [..., n] -> [...] (xi^T Q xi, float64 numpy)."""
  q = check_q(q)
  arg_checks.check_real_dtype("lights", lights)
  lights = np.asarray(lights, np.float64)
  if lights.ndim < 1 or lights.shape[-1] != q.shape[0]:
    raise ValueError(f"lights must have shape [..., {q.shape[0]}] (the n of q), got "
                     f"{list(lights.shape)}")
  return np.einsum("...i,ij,...j->...", lights, q, lights)


def top_eigen(q):
  """(largest eigenvalue, its unit eigenvector [n]) of the symmetric Q (float64 numpy)."""
  values, vectors = np.linalg.eigh(check_q(q))
  return float(values[-1]), vectors[:, -1]
