"""Per-pixel uncertainty maps of every method, and the depth error they are judged against.

For a test camera and a trained model:

* depth error: e(p) = |d(p) - d*(p)|, d = the model's expected depth (depth / alpha of its
  mean render), d* the exact depth of the capture, counted where the capture's alpha is 1
  and the model's is above 0.5 (`depth_error`);
* Ours (any sampler), from M samples theta(z_m) of the field (`sample_maps`):
  colour U(p) = (1/M) sum_m ||C_m(p) - C_mean(p)||^2 (Eq. 10's per-pixel term), and the
  variance over the samples of their expected depth d_m(p), which the paper does not report;
* FisherRF: `mfsample.baselines.fisher.fisher_pixel_variance`, the per-pixel terms of its
  candidate score, with H over the training views;
* ActiveNeRF: the rendered variance beta^2(p) of `mfsample.baselines.activenerf`.
"""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np

from mfsample.baselines.activenerf import rendered_variance
from mfsample.model import mean_gaussians
from mfsample.renderer import RenderSettings, TileStats, render
from mfsample.view_uncertainty import pixel_variance, sample_gaussians


class SampleMaps(NamedTuple):
  """Ours' per-pixel maps from M samples.

  Attributes:
    colour: [H, W] U(p), Eq. 10's per-pixel variance of the colour, summed over RGB.
    depth: [H, W] variance over the samples of their expected depth.
    stats: `TileStats` [M].
  """

  colour: chex.Array
  depth: chex.Array
  stats: TileStats


@functools.partial(jax.jit, static_argnames=("settings",))
def sample_maps(model, camera, z, background, *, settings: RenderSettings) -> SampleMaps:
  """Ours' colour and depth maps from the samples theta(z_m), z: `[M, *z_shape]`.

  The samples are rendered one after another (`lax.map`), as `uncertainty.uncertainty` does.
  """
  def one(g):
    out = render(g, camera, background=background, settings=settings)
    return out.rgb, out.expected_depth(), out.stats

  rgbs, depths, stats = jax.lax.map(one, sample_gaussians(model, z))
  return SampleMaps(pixel_variance(rgbs), jnp.var(depths, axis=0), stats)


@functools.partial(jax.jit, static_argnames=("settings",))
def activenerf_map(vmodel, camera, *, settings: RenderSettings):
  """ActiveNeRF's per-pixel variance beta^2(p) of a fitted `activenerf.VarianceModel`, and the
  render's `TileStats`."""
  return rendered_variance(mean_gaussians(vmodel.model), vmodel.log_var, camera,
                           vmodel.beta_min, settings=settings)


def depth_error(depth, alpha, true_depth, true_alpha, *, true_alpha_min, model_alpha_min):
  """|d - d*| and where it counts (numpy).

  Args:
    depth: [H, W] the model's expected depth.
    alpha: [H, W] the model's coverage.
    true_depth: [H, W] exact depth of the capture.
    true_alpha: [H, W] the capture's coverage.
    true_alpha_min: count pixels whose true alpha is at least this (fully covered).
    model_alpha_min: ... and whose model alpha is above this.

  Returns:
    (error [H, W] float64 >= 0, mask [H, W] bool).
  """
  error = np.abs(np.asarray(depth, np.float64) - np.asarray(true_depth, np.float64))
  mask = (np.asarray(true_alpha) >= true_alpha_min) & (np.asarray(alpha) > model_alpha_min)
  return error, mask
