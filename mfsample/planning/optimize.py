"""Next-best-view optimisation: Adam on -U w.r.t. the camera (paper Sec. 4.4).

The authors' recipe (their `active_dcam.py`): the camera on the sphere of the spherical
parameterisation (`poses`), Adam with lr 5e-4 on (u, v) for 400 steps, M = 2 Sobol samples
z, scaled by 0.1 from step 200 on (so the second half follows a more local, smoother
variance), u wrapped and v clamped after every step. `optimize_spherical` runs exactly that
with every number an `OptimizeSettings` field; `optimize_se3` runs the same loop on a free
6-DoF pose updated in the tangent space (`poses.perturb_camera`).

With `resample_z` every step draws M fresh z (uniform on [-1, 1], from a PRNG key) instead
of reusing the same M: Adam then follows stochastic gradients of the expected U, the
quantity that Eq. 10 estimates, rather than exact gradients of one fixed M-sample
estimate. The authors' published optimisation command (`--rank 0`, a diagonal sampler)
draws fresh uniforms every step in this way.

The whole trajectory is one `lax.scan` (a single compilation, no host round trip per step);
if any render overflowed its intersection budget the run is repeated with a larger budget, so
no step ever follows the gradient of a truncated image.
"""

import dataclasses
import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax

from mfsample import arg_checks
from mfsample import settings_checks as sc
from mfsample.camera import Camera
from mfsample.planning import poses
from mfsample.renderer.budget import render_with_budget
from mfsample.renderer.settings import RenderSettings
from mfsample.sharding import default_num_devices
from mfsample.view_uncertainty import (
    check_inputs,
    inputs_ok,
    sample_gaussians,
    uncertainty_of_samples,
)


@dataclasses.dataclass(frozen=True)
class OptimizeSettings:
  """Static settings of the camera optimisation (authors' values as defaults).

  Attributes:
    steps: Adam steps (authors: 400).
    lr: Adam learning rate on (u, v) (authors: 5e-4).
    z_drop_step: from this step on z is multiplied by `z_drop_scale` (authors: 200).
    z_drop_scale: (authors: 0.1).
    resample_z: draw fresh z every step (shaped like the given z) instead of reusing it.
    se3_lr_rotation: Adam learning rate of the rotation part of a 6-DoF tangent vector
      (radians per step, roughly).
    se3_lr_translation: the same for the translation part (world units per step).
  """

  steps: int = 400
  lr: float = 5e-4
  z_drop_step: int = 200
  z_drop_scale: float = 0.1
  resample_z: bool = False
  se3_lr_rotation: float = 2e-3
  se3_lr_translation: float = 5e-3

  def __post_init__(self):
    sc.check_int("OptimizeSettings.steps", self.steps, minimum=1)
    sc.check_int("OptimizeSettings.z_drop_step", self.z_drop_step, minimum=0)
    # At most 1: a scaled z must stay in z's range [-1, 1].
    sc.check_float("OptimizeSettings.z_drop_scale", self.z_drop_scale, minimum=0.0,
                   maximum=1.0)
    for name in ("lr", "se3_lr_rotation", "se3_lr_translation"):
      # 0 is allowed: the pose stays where selection put it (the optimiser's ablation).
      sc.check_float(f"OptimizeSettings.{name}", getattr(self, name), minimum=0.0)
    sc.check_bool("OptimizeSettings.resample_z", self.resample_z)


class OptimizeResult(NamedTuple):
  """What an optimisation returns.

  Attributes:
    camera: the final unbatched `Camera`.
    params: final parameters ((u, v) [2] or xi [6]).
    values: [steps] U at the start of every step (with that step's z scale).
    trajectory: [steps + 1, P] parameters before every step and after the last.
    settings: `RenderSettings` that sufficed.
  """

  camera: object
  params: chex.Array
  values: chex.Array
  trajectory: chex.Array
  settings: RenderSettings


def _z_scales(opt: OptimizeSettings, dtype):
  steps = np.arange(opt.steps)
  return jnp.asarray(np.where(steps >= opt.z_drop_step, opt.z_drop_scale, 1.0), dtype)


def _run(model, params0, z, key, background, camera_fn, project, optimizer, opt, settings,
         num_devices):
  """The scanned Adam loop on -U(camera_fn(params)); the M samples split over devices."""

  def neg_u(params, z_step):
    g = sample_gaussians(model, z_step)
    u = uncertainty_of_samples(g, camera_fn(params), settings=settings, background=background,
                               num_devices=num_devices)
    return -u.value, u.stats

  def step(carry, xs):
    params, state = carry
    index, z_scale = xs
    if opt.resample_z:
      z_step = jax.random.uniform(jax.random.fold_in(key, index), z.shape, z.dtype, -1.0, 1.0)
    else:
      z_step = z
    (loss, stats), grad = jax.value_and_grad(neg_u, has_aux=True)(params, z_step * z_scale)
    updates, state = optimizer.update(grad, state, params)
    new = project(optax.apply_updates(params, updates))
    return (new, state), (-loss, params, jnp.max(stats.num_padded), jnp.any(stats.overflow))

  init = (params0, optimizer.init(params0))
  (params, _), (values, traj, num_padded, overflow) = jax.lax.scan(
      step, init, (jnp.arange(opt.steps), _z_scales(opt, z.dtype)))
  trajectory = jnp.concatenate([traj, params[None]], axis=0)
  # Values that could not raise (traced): a NaN pose and U, never a plausible ascent.
  ok = inputs_ok(model, z, background)
  params, values, trajectory = (arg_checks.nan_unless(ok, x) for x in (params, values,
                                                                      trajectory))
  return params, values, trajectory, jnp.max(num_padded), jnp.any(overflow)


@functools.partial(jax.jit, static_argnames=("sphere", "opt", "settings", "num_devices"))
def _spherical(model, uv0, z, key, background, *, sphere, opt, settings, num_devices):
  optimizer = optax.adam(opt.lr)
  return _run(model, uv0, z, key, background, lambda uv: poses.spherical_camera(uv, sphere),
              lambda uv: poses.project_uv(uv, sphere), optimizer, opt, settings, num_devices)


@functools.partial(jax.jit, static_argnames=("opt", "settings", "num_devices"))
def _se3(model, camera0, z, key, background, *, opt, settings, num_devices):
  # Rotation and translation differ in units: one learning rate each.
  lrs = jnp.asarray([opt.se3_lr_rotation] * 3 + [opt.se3_lr_translation] * 3, z.dtype)
  optimizer = _per_coordinate_adam(lrs)
  xi0 = jnp.zeros((6,), z.dtype)
  return _run(model, xi0, z, key, background, lambda xi: poses.perturb_camera(camera0, xi),
              lambda xi: xi, optimizer, opt, settings, num_devices)


@functools.partial(jax.jit, static_argnames=("sphere", "opt", "settings", "num_devices"))
def _orbit(model, uv0, camera0, z, key, background, *, sphere, opt, settings, num_devices):
  optimizer = optax.adam(opt.lr)
  return _run(model, uv0, z, key, background,
              lambda uv: poses.orbit_camera(uv, camera0, sphere),
              lambda uv: poses.project_uv(uv, sphere), optimizer, opt, settings, num_devices)


def _per_coordinate_adam(lrs):
  """Adam (descent) whose step size is `lrs` [6] per coordinate."""
  def init(params):
    del params
    return optax.EmptyState()

  def update(updates, state, params=None):
    del params
    return -lrs * updates, state

  return optax.chain(optax.scale_by_adam(), optax.GradientTransformation(init, update))


def _with_budget(run, settings, max_budget):
  """`run(settings)` -> (*results, num_padded, overflow), grown until nothing overflows."""
  out, settings = render_with_budget(
      lambda *, settings: run(settings), settings, max_budget=max_budget,
      stats_of=lambda out: _Overflow(num_padded=out[-2], overflow=out[-1]),
      what="view optimisation")
  return out[:-2], settings


def _key(opt: OptimizeSettings, key):
  if key is not None:
    return key
  if opt.resample_z:
    raise ValueError("OptimizeSettings.resample_z needs a PRNG key")
  return jax.random.PRNGKey(0)  # unused


class _Overflow(NamedTuple):
  num_padded: chex.Array
  overflow: chex.Array


def _check_common(model, z, background, num_devices, max_budget):
  """(background [3], number of devices) after checking the arguments both optimisers take."""
  check_inputs(model, z, background, sync=True)  # called once, it syncs anyway
  arg_checks.check_int("max_budget", max_budget, minimum=1)
  dtype = model.params.mean["means"].dtype
  background = jnp.zeros((3,), dtype) if background is None else jnp.asarray(background, dtype)
  n = default_num_devices(z.shape[0]) if num_devices is None else num_devices
  return background, arg_checks.check_int("num_devices", n, minimum=1,
                                          maximum=jax.device_count())


def optimize_spherical(model, uv0, z, *, sphere: poses.SphereSpec, opt=OptimizeSettings(),
                       settings: RenderSettings = RenderSettings(), background=None,
                       num_devices=None, max_budget=1 << 24, key=None) -> OptimizeResult:
  """Maximises U over the camera sphere from (u, v) = `uv0` (Ours (Opt. Sel. / Rnd.)).

  Args:
    model: stochastic `mfsample.model.Model`.
    uv0: [2] starting (u, v) (projected onto the valid band first).
    z: `[M, *z_shape]` samples (`mfsample.samplers.sample_z`; paper M = 2); with
      `opt.resample_z` only its shape is used.
    sphere: `poses.SphereSpec` (static; its image size is the optimisation's resolution).
    opt: `OptimizeSettings`.
    settings: starting `RenderSettings` (grown on overflow).
    background: [3] colour (default black).
    num_devices: devices to split the M samples over (default: as many as there are samples
      and devices).
    max_budget: refuse to grow the render budget beyond this.
    key: PRNG key of the fresh z (required with `opt.resample_z`, ignored otherwise).

  Returns:
    `OptimizeResult`.
  """
  arg_checks.check_shape("uv0", uv0, (2,))
  arg_checks.check_finite("uv0", uv0)
  background, n = _check_common(model, z, background, num_devices, max_budget)
  dtype = model.params.mean["means"].dtype
  uv0 = poses.project_uv(jnp.asarray(uv0, dtype), sphere)
  (params, values, traj), settings = _with_budget(
      lambda s: _spherical(model, uv0, z, _key(opt, key), background, sphere=sphere, opt=opt,
                           settings=s, num_devices=n), settings, max_budget)
  return OptimizeResult(poses.spherical_camera(params, sphere), params, values, traj, settings)


def optimize_se3(model, camera0, z, *, opt=OptimizeSettings(),
                 settings: RenderSettings = RenderSettings(), background=None,
                 num_devices=None, max_budget=1 << 24, key=None) -> OptimizeResult:
  """Maximises U over free 6-DoF poses near `camera0` (tangent-space Adam on xi).

  Unlike the spherical parameterisation nothing keeps the camera pointed at the scene or at
  a fixed distance; use it for small refinements.

  Returns:
    `OptimizeResult` with params = xi [6] and camera = perturb_camera(camera0, xi).
  """
  if not isinstance(camera0, Camera) or camera0.batch_shape:
    raise ValueError("camera0 must be one unbatched Camera, got "
                     + (f"a batch {camera0.batch_shape}" if isinstance(camera0, Camera)
                        else type(camera0).__name__))
  background, n = _check_common(model, z, background, num_devices, max_budget)
  (params, values, traj), settings = _with_budget(
      lambda s: _se3(model, camera0, z, _key(opt, key), background, opt=opt, settings=s,
                     num_devices=n), settings, max_budget)
  return OptimizeResult(poses.perturb_camera(camera0, params), params, values, traj, settings)


def optimize_orbit(model, camera0, z, *, target=(0.0, 0.0, 0.0), v_range=(0.01, 0.99),
                   opt=OptimizeSettings(), settings: RenderSettings = RenderSettings(),
                   background=None, num_devices=None, max_budget=1 << 24,
                   key=None) -> OptimizeResult:
  """Maximises U over the sphere about `target` through `camera0` (the paper's ascent from
  a start pose): the camera keeps its distance to `target` and looks at it (up +z), with
  `camera0`'s intrinsics; (u, v) as `poses.spherical_camera`, v clamped to `v_range`.

  Returns:
    `OptimizeResult` with params = (u, v) [2].
  """
  if not isinstance(camera0, Camera) or camera0.batch_shape:
    raise ValueError("camera0 must be one unbatched Camera, got "
                     + (f"a batch {camera0.batch_shape}" if isinstance(camera0, Camera)
                        else type(camera0).__name__))
  arg_checks.check_shape("target", target, (3,))
  arg_checks.check_finite("target", np.asarray(target, np.float64))
  background, n = _check_common(model, z, background, num_devices, max_budget)
  center = tuple(float(c) for c in np.asarray(target, np.float64))
  eye = np.asarray(camera0.center, np.float64)
  radius = float(np.linalg.norm(eye - np.asarray(center)))
  if not radius > 0:
    raise ValueError(f"camera0 sits at target {list(center)}: the orbit needs a radius > 0")
  sphere = poses.SphereSpec(center=center, radius=radius, v_range=tuple(v_range),
                            width=camera0.width, height=camera0.height)
  dtype = model.params.mean["means"].dtype
  uv0 = poses.project_uv(jnp.asarray(poses.camera_to_uv(camera0, center), dtype), sphere)
  (params, values, traj), settings = _with_budget(
      lambda s: _orbit(model, uv0, camera0, z, _key(opt, key), background, sphere=sphere,
                       opt=opt, settings=s, num_devices=n), settings, max_budget)
  return OptimizeResult(poses.orbit_camera(params, camera0, sphere), params, values, traj,
                        settings)
