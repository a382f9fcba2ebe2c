"""Jitted renders of a model's mean Gaussians: one camera, or a batch of cameras.

The renders every job evaluates a model with (test metrics, errors at candidates, depth
errors, the baselines' fits): one definition, so equal settings share one compilation.
"""

import functools

import jax
import jax.numpy as jnp

from mfsample.model import mean_gaussians
from mfsample.renderer import render


@functools.partial(jax.jit, static_argnames=("settings",))
def render_mean(model, camera, background, *, settings):
  """`render` of the model's mean Gaussians (jitted; settings static)."""
  return render(mean_gaussians(model), camera, background=background, settings=settings)


@functools.partial(jax.jit, static_argnames=("settings",))
def render_mean_views(model, cameras, background, *, settings):
  """([V, H, W, 3] renders of the mean model clipped to [0, 1], `TileStats` [V]) of a batch
  of cameras, rendered one after another (`lax.map`: each render skips its unused budget)."""
  gaussians = mean_gaussians(model)

  def one(camera):
    out = render(gaussians, camera, background=background, settings=settings)
    return jnp.clip(out.rgb, 0.0, 1.0), out.stats

  return jax.lax.map(one, cameras)
