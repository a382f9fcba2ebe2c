"""ActiveNeRF-style variance (Pan et al. 2022), adapted to 3DGS: a light, documented version.

ActiveNeRF models every radiance sample as a Gaussian with a learned variance, composites
the variance along the ray, trains it with the heteroscedastic negative log-likelihood, and
picks the candidate view whose rendered variance is largest (FisherRF's 3DGS port scores
the reduction from prior to posterior variance). Here, for 3DGS:

* every Gaussian i carries a variance v_i = exp(s_i) (a per-Gaussian feature);
* a pixel's variance is beta^2(p) = beta_min + sum_i w_i(p) v_i, composited with the
  ordinary blending weights w_i = alpha_i T_i through `render(..., features=...)`
  (ActiveNeRF and FisherRF's port weight by w_i^2, the variance of a weighted sum of
  independent samples; our renderer composites features linearly, and the linear weights
  keep the ranking property that matters: unseen Gaussians keep a high variance);
* s is fitted after the colour model (a two-stage fit: geometry and colours frozen, which
  keeps the planning rounds on the shared training code) by Adam on the NLL

    L = mean_p [ ||C(p) - C_hat(p)||^2 / (2 beta^2(p)) + log(beta^2(p)) / 2 ]
        + prior_weight * mean_i (s_i - s_0)^2,

  one training view per step; Gaussians no training view sees keep the prior s_0;
* a candidate's score is the rendered variance above the floor summed over its pixels,
  sum_p (beta^2(p) - beta_min) (the floor shifts every candidate alike).
"""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax

from mfsample.model import mean_gaussians
from mfsample.renderer import RenderSettings, render
from mfsample.renderer.budget import render_with_budget
from mfsample.sharding import map_cameras
from mfsample.train.evaluate import render_mean


class VarianceModel(NamedTuple):
  """A deterministic colour model plus a per-Gaussian log-variance.

  Attributes:
    model: `mfsample.model.Model` (deterministic; its mean is used).
    log_var: [C] s_i, log of each Gaussian's variance.
    beta_min: scalar variance floor of every pixel.
  """

  model: object
  log_var: chex.Array
  beta_min: chex.Array


def rendered_variance(gaussians, log_var, camera, beta_min, *, settings: RenderSettings):
  """[H, W] beta^2 = beta_min + sum_i w_i exp(s_i), and the render's `TileStats`."""
  out = render(gaussians, camera, settings=settings, features=jnp.exp(log_var)[:, None],
               background=jnp.zeros((1,), log_var.dtype))
  return beta_min + out.rgb[..., 0], out.stats


def nll(log_var, gaussians, camera, target, prediction, beta_min, prior_log_var,
        prior_weight, mask, *, settings):
  """The heteroscedastic NLL of one view plus the prior on live Gaussians (module doc)."""
  beta2, stats = rendered_variance(gaussians, log_var, camera, beta_min, settings=settings)
  sq = jnp.sum(jnp.square(target - prediction), axis=-1)
  data = jnp.mean(0.5 * sq / beta2 + 0.5 * jnp.log(beta2))
  live = mask.astype(log_var.dtype)
  prior = jnp.sum(live * jnp.square(log_var - prior_log_var)) / jnp.maximum(jnp.sum(live), 1)
  return data + prior_weight * prior, stats


@functools.partial(jax.jit, static_argnames=("settings", "steps", "lr"))
def _fit(model, images, predictions, cameras, order, beta_min, prior_log_var, prior_weight,
         *, settings, steps, lr):
  gaussians = mean_gaussians(model)
  log_var = jnp.full((model.capacity,), prior_log_var, images.dtype)
  opt = optax.adam(lr)

  def step(carry, view):
    s, state = carry
    (loss, stats), grad = jax.value_and_grad(nll, has_aux=True)(
        s, gaussians, cameras[view], images[view], predictions[view], beta_min,
        prior_log_var, prior_weight, model.mask, settings=settings)
    updates, state = opt.update(grad, state, s)
    return (optax.apply_updates(s, updates), state), (loss, stats.overflow)

  (log_var, _), (losses, overflow) = jax.lax.scan(step, (log_var, opt.init(log_var)), order)
  return log_var, losses, jnp.any(overflow)


def fit_variance(model, views, *, settings: RenderSettings, background, steps=60, lr=0.05,
                 prior_var=0.05, beta_min=1e-3, prior_weight=1e-3, seed=0, pad_to=None):
  """Fits the per-Gaussian log-variance of `model` on the training `views` (module doc).

  Args:
    model: deterministic `mfsample.model.Model`, trained on `views`.
    views: training `Views` (images [V, H, W, 3], cameras [V]).
    settings: `RenderSettings` whose budget holds the views.
    background: [3] colour behind the Gaussians.
    steps: Adam steps (one view each, in seeded random order).
    lr: Adam learning rate of s.
    prior_var: exp(s_0), the variance of Gaussians no view constrains.
    beta_min: variance floor of every pixel.
    prior_weight: weight of the quadratic prior on s.
    seed: seed of the view order.
    pad_to: pad the views to this many slots (never drawn), so that one compilation serves
      every round of the protocol.

  Returns:
    (`VarianceModel`, losses [steps]).
  """
  dtype = model.params.mean["means"].dtype
  background = jnp.asarray(background, dtype)
  images = jnp.asarray(views.images, dtype)
  preds = []
  for i in range(len(views)):
    out, settings = render_with_budget(render_mean, settings, model, views.cameras[i],
                                       background)
    preds.append(out.rgb)
  order = np.random.default_rng([int(seed), 11]).integers(0, len(views), int(steps))
  slots = np.minimum(np.arange(max(len(views), pad_to or 0)), len(views) - 1)
  log_var, losses, overflow = _fit(model, images[slots], jnp.stack(preds)[slots],
                                   views.cameras[slots],
                                   jnp.asarray(order, jnp.int32), jnp.asarray(beta_min, dtype),
                                   jnp.asarray(np.log(prior_var), dtype),
                                   jnp.asarray(prior_weight, dtype), settings=settings,
                                   steps=int(steps), lr=float(lr))
  if bool(overflow):  # the budget was sized on these very views: cannot happen
    raise RuntimeError("variance fit overflowed its render budget")
  return VarianceModel(model, log_var, jnp.asarray(beta_min, dtype)), np.asarray(losses)


@functools.partial(jax.jit, static_argnames=("settings", "num_devices"))
def _variance_scores(vmodel, cameras, *, settings, num_devices):
  gaussians = mean_gaussians(vmodel.model)

  def one(camera, g, s):
    beta2, stats = rendered_variance(g, s, camera, 0.0, settings=settings)
    return jnp.sum(beta2), stats

  return map_cameras(one, cameras, gaussians, vmodel.log_var, num_devices=num_devices)


def variance_scores(vmodel: VarianceModel, cameras, *, settings: RenderSettings,
                    num_devices=1):
  """[B] ActiveNeRF-style scores: rendered variance sum_p (beta^2(p) - beta_min).

  Returns (scores [B] numpy, settings that sufficed).
  """
  (values, _), settings = render_with_budget(
      _variance_scores, settings, vmodel, cameras, num_devices=num_devices,
      stats_of=lambda out: out[1], what="variance scoring")
  return np.asarray(values), settings
