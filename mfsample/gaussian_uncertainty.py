"""Uncertainty per Gaussian: where in the model the per-pixel U of Eq. 10 comes from.

U is a property of pixels (`mfsample.uncertainty`). A splat viewer shows Gaussians, so the
pixel variance is handed back to the Gaussians that make those pixels, and two spreads of
B_hat are read off per Gaussian:

* share_g: the part of U that Gaussian g is responsible for,

    share_g = sum_v sum_p w_g^v(p) var_v(p),

  summed over the views v and their pixels p, where var_v(p) = (1/M) sum_m
  ||C_m(p) - C_mean(p)||^2 is the per-pixel variance of Eq. 10 over the M samples theta(z_m)
  seen from view v (the uncertainty map, held constant), and w_g^v(p) = alpha_g(p) T_g(p) is
  g's blending weight at p in the mean model's render (its alpha there times the
  transmittance in front of it). The weights of a pixel sum to its opacity 1 - T_final(p), so

    sum_g share_g = sum_v sum_p (1 - T_final^v(p)) var_v(p) <= sum_v U_v,

  with equality where the mean render is opaque: the shares split the U of the views among
  the Gaussians, and what is left is the variance seen against the background.

* position_std_g = sqrt(Var x_g + Var y_g + Var z_g): the spread of g's centre over
  theta(z) (world units), from B_hat (`mfsample.samplers.entry_variance`: sum_j B_hat_j^2 / 3
  per entry for z ~ U[-1, 1]);
* colour_std_g = SH_C0 sqrt(sum_c Var f_dc,c): the spread of g's base colour, in RGB units
  (the DC colour is 0.5 + SH_C0 f_dc, SH_C0 = 0.2821).

Both spreads are 0 for the groups the sampler leaves deterministic, and every field is 0 on
padding rows.

No new renderer code computes the weights: rendering the mean Gaussians with one scalar
feature x_g each blends C_x(p) = sum_g w_g(p) x_g (`render(..., features=x[:, None])`, over a
zero background), so

  d/dx_g sum_p var(p) C_x(p) = sum_p w_g(p) var(p),

one forward and one backward pass per view, evaluated at x = 1 (the value of x does not
matter: C_x is linear in x).
"""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks, samplers
from mfsample.camera import Camera
from mfsample.model import mean_gaussians
from mfsample.renderer import render
from mfsample.renderer.budget import render_with_budget
from mfsample.renderer.settings import RenderSettings
from mfsample.renderer.sh import sh_basis
from mfsample.view_uncertainty import (
    check_inputs,
    inputs_ok,
    sample_gaussians,
    uncertainty_of_samples,
)


class GaussianUncertainty(NamedTuple):
  """Uncertainty per Gaussian (see the module docstring for the definitions).

  Attributes:
    share: [C] float32: sum over the views and pixels of g's blending weight times the
      per-pixel variance of Eq. 10 (units of U: squared colour, summed over RGB).
    position_std: [C] float32: standard deviation of g's centre over theta(z), the root of
      the summed variances of x, y and z (world units).
    colour_std: [C] float32: standard deviation of g's DC colour over theta(z), the root of
      the summed variances of R, G and B (colour units).
  All three are 0 on padding rows (C is the model's capacity).
  """

  share: chex.Array
  position_std: chex.Array
  colour_std: chex.Array


@functools.partial(jax.jit, static_argnames=("settings",))
def view_share(model, camera: Camera, z, background, *, settings: RenderSettings):
  """The share of one view: ([C] sum_p w_g(p) var(p), [H, W] var, stats of every render).

  Args:
    model: `mfsample.model.Model`.
    camera: one unbatched `Camera`.
    z: `[M, *samplers.z_shape(model)]` samples.
    background: [3] colour behind the samples (the one the model was trained on).
    settings: `RenderSettings` (static).

  Returns:
    (share [C], pixel variance [H, W], `TileStats` [M + 1]: the M sample renders and the
    mean render; check `overflow`).
  """
  unc = uncertainty_of_samples(sample_gaussians(model, z), camera, settings=settings,
                               background=background)
  variance = jax.lax.stop_gradient(unc.pixel_map)
  gaussians = mean_gaussians(model)

  def weighted_variance(x):
    out = render(gaussians, camera, settings=settings, features=x[:, None])
    return jnp.sum(out.rgb[..., 0] * variance), out.stats

  ones = jnp.ones((model.capacity,), variance.dtype)
  share, mean_stats = jax.grad(weighted_variance, has_aux=True)(ones)
  ok = inputs_ok(model, z, background)  # traced values cannot raise: NaN, never finite
  share, variance = arg_checks.nan_unless(ok, share), arg_checks.nan_unless(ok, variance)
  stats = jax.tree.map(lambda s, m: jnp.concatenate([jnp.atleast_1d(s), m[None]]), unc.stats,
                       mean_stats)
  return share, variance, stats


def spreads(model):
  """([C] position_std, [C] colour_std) of the model's B_hat (0 where not stochastic)."""
  variance = samplers.entry_variance(model) if model.spec.stochastic else {}
  zeros = jnp.zeros((model.capacity,), jnp.float32)

  def root_sum(group):
    if group not in variance:
      return zeros
    v = variance[group].reshape(model.capacity, -1)
    return jnp.sqrt(jnp.sum(v, axis=-1)).astype(jnp.float32)

  dc_to_rgb = sh_basis(jnp.array([0.0, 0.0, 1.0]), 0)[0]  # SH_C0: colour = 0.5 + SH_C0 f_dc
  mask = model.mask
  return (jnp.where(mask, root_sum("means"), 0.0),
          jnp.where(mask, dc_to_rgb * root_sum("sh_dc"), 0.0))


def gaussian_uncertainty(model, cameras: Camera, z, *, settings: RenderSettings,
                         background=None) -> GaussianUncertainty:
  """Uncertainty per Gaussian of `model` over the views `cameras` (module docstring).

  Args:
    model: `mfsample.model.Model` (any sampler; a deterministic one has share 0).
    cameras: `Camera`, one or batched over [V]; the views the shares are summed over (e.g.
      the training views, or the candidates of the next views).
    z: `[M, *samplers.z_shape(model)]` samples of theta (`mfsample.samplers.sample_z`).
    settings: `RenderSettings` to start from; the intersection budget is grown on overflow
      (`render_with_budget`), never truncated.
    background: [3] colour behind the sample renders (default black), as for U.

  Returns:
    `GaussianUncertainty` of numpy float32 arrays [C].
  """
  if not isinstance(cameras, Camera):
    raise TypeError(f"cameras must be a mfsample.Camera, got {type(cameras).__name__}")
  if len(cameras.batch_shape) > 1:
    raise ValueError(f"cameras must be one camera or a batch [V], got batch shape "
                     f"{cameras.batch_shape}")
  check_inputs(model, z, background, sync=True)  # it synchronises anyway
  dtype = model.params.mean["means"].dtype
  background = jnp.zeros((3,), dtype) if background is None else jnp.asarray(background, dtype)
  share = np.zeros((model.capacity,), np.float64)
  views = [cameras] if not cameras.batch_shape else [cameras[i] for i in range(len(cameras))]
  for camera in views:
    (view, _, _), settings = render_with_budget(
        view_share, settings, model, camera, z, background, stats_of=lambda out: out[2],
        what="gaussian uncertainty")
    share += np.asarray(view, np.float64)
  position_std, colour_std = spreads(model)
  live = np.asarray(model.mask, bool)
  return GaussianUncertainty(share=np.where(live, share, 0.0).astype(np.float32),
                             position_std=np.asarray(position_std, np.float32),
                             colour_std=np.asarray(colour_std, np.float32))
