"""FisherRF (Jiang et al. 2024): next views by the diagonal Fisher information of the model.

For a deterministic 3DGS model with raw parameters theta and a camera whose render is
I(theta) [H, W, 3], the diagonal of the Fisher information (Gauss-Newton Hessian of an L2
loss) is, per parameter d,

  H_d = sum over pixels p and channels c of (dI_pc / dtheta_d)^2 = diag(J^T J)_d.

FisherRF computes it with a modified CUDA backward that squares per-pixel gradients. Here it
is estimated without bias with Rademacher probes: for v in {-1, +1}^(H W 3),

  E_v[(J^T v)_d^2] = sum_{p, q} J_pd J_qd E[v_p v_q] = sum_p J_pd^2 = H_d,

so K probes cost K vector-Jacobian products (one backward pass each) per camera
(`fisher_diagonal`). `fisher_diagonal_exact` forms J column by column and is meant for tiny
images (tests check the estimator against it). The candidate score is FisherRF's

  score(c) = sum_d H_d(c) / (H_d(train) + lambda),   lambda = 1e-6,

with H(train) accumulated over the training views, and the candidate with the highest score
is selected. As in FisherRF's default (`--filter_out_grad rotation`), the rotation
parameters are left out (config `groups`). All candidates share the same probes (common
random numbers: each score is still unbiased, and their differences are less noisy).

The score is a sum over pixels: with D = diag(1 / (H(train) + lambda)),

  score(c) = sum_p u(p),   u(p) = sum_c' sum_d D_d (dI_pc' / dtheta_d)^2 = (J D J^T)_pp,

u(p) being the diagonal Laplace approximation's predictive variance of pixel p's colour: the
per-pixel uncertainty map of FisherRF (`fisher_pixel_variance`). It is estimated with
probes on the parameter side: for w in {-1, +1}^d, E_w[(J D^(1/2) w)_p^2] = u(p), so K probes
cost K forward-mode Jacobian-vector products per camera and give the whole map at once.
"""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np

from mfsample.model import activate
from mfsample.renderer import RenderSettings, render
from mfsample.renderer.budget import render_with_budget
from mfsample.sharding import map_cameras

# FisherRF leaves the rotations out (its default `--filter_out_grad rotation`).
DEFAULT_GROUPS = ("means", "log_scales", "opacity_logits", "sh_dc", "sh_rest")


def _split(mean, groups):
  diff = {g: v for g, v in mean.items() if g in groups}
  rest = {g: v for g, v in mean.items() if g not in groups}
  return diff, rest


def _image_fn(model, camera, background, settings, groups):
  """(differentiable params, fn: params -> (rgb [H, W, 3], stats))."""
  diff, rest = _split(model.params.mean, groups)

  def image(params):
    g = activate({**rest, **params}, model.mask, model.sh_degree)
    out = render(g, camera, background=background, settings=settings)
    return out.rgb, out.stats

  return diff, image


def rademacher(key, shape, dtype=jnp.float32):
  """Independent +-1 entries with probability 1/2 each."""
  return jnp.where(jax.random.bernoulli(key, 0.5, shape), 1.0, -1.0).astype(dtype)


def fisher_diagonal_from_probes(model, camera, probes, *, settings: RenderSettings,
                                background, groups=DEFAULT_GROUPS):
  """mean_k (J^T v_k)^2 over given probes v_k [K, H, W, 3] (K vector-Jacobian products).

  With Rademacher probes this is an unbiased estimate of H = diag(J^T J); with the K = H W 3
  unit vectors it is H / K exactly (`fisher_diagonal_exact`).

  Returns:
    ({group: [C, ...]}, `TileStats` of the render).
  """
  diff, image = _image_fn(model, camera, background, settings, groups)
  _, vjp, stats = jax.vjp(image, diff, has_aux=True)
  grads = jax.lax.map(lambda v: vjp(v)[0], probes)  # sequential: memory of one backward
  return jax.tree.map(lambda g: jnp.mean(jnp.square(g), axis=0), grads), stats


def fisher_diagonal(model, camera, key, *, num_probes, settings: RenderSettings, background,
                    groups=DEFAULT_GROUPS):
  """Unbiased estimate of H = diag(J^T J) of one camera with `num_probes` Rademacher probes.

  Args:
    model: `mfsample.model.Model` (its mean parameters are used).
    camera: unbatched `Camera`.
    key: PRNG key of the probes.
    num_probes: K (static): K vector-Jacobian products.
    settings: `RenderSettings` (static).
    background: [3] colour.
    groups: raw parameter groups to differentiate.

  Returns:
    ({group: [C, ...]} estimate of H, `TileStats` of the render).
  """
  shape = (num_probes, camera.height, camera.width, 3)
  probes = rademacher(key, shape, model.params.mean["means"].dtype)
  return fisher_diagonal_from_probes(model, camera, probes, settings=settings,
                                     background=background, groups=groups)


def fisher_diagonal_exact(model, camera, *, settings: RenderSettings, background,
                          groups=DEFAULT_GROUPS):
  """The exact H = sum over pixels and channels of (dI/dtheta)^2 (H W 3 backward passes).

  Only for tiny images: the reference that the probe estimator is tested against.
  """
  k = camera.height * camera.width * 3
  basis = jnp.eye(k, dtype=model.params.mean["means"].dtype).reshape(
      (k, camera.height, camera.width, 3))
  h, _ = fisher_diagonal_from_probes(model, camera, basis, settings=settings,
                                     background=background, groups=groups)
  return jax.tree.map(lambda x: k * x, h)


class FisherScores(NamedTuple):
  """FisherRF scores of a batch of candidates.

  Attributes:
    values: [B] candidate scores.
    h_train: {group: [C, ...]} H accumulated over the training views.
    num_padded: int32, the largest padded intersection count of any render.
    overflow: bool, some render exceeded the budget (the scores are then invalid).
  """

  values: chex.Array
  h_train: dict
  num_padded: chex.Array
  overflow: chex.Array


@functools.partial(jax.jit, static_argnames=("settings", "num_probes", "train_probes",
                                             "groups", "num_devices"))
def _fisher_scores(model, train_cameras, train_weights, candidates, key, background, reg, *,
                   settings, num_probes, train_probes, groups, num_devices):
  k_train, k_cand = jax.random.split(key)
  train_keys = jax.random.split(k_train, train_cameras.batch_shape[0])

  def train_one(inputs):
    camera, k, w = inputs

    def compute(_):
      return fisher_diagonal(model, camera, k, num_probes=train_probes, settings=settings,
                             background=background, groups=groups)

    def skip(_):  # a padding slot (weight 0): no backward passes
      return jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), jax.eval_shape(compute, None))

    return jax.lax.cond(w > 0, compute, skip, None)

  h_views, train_stats = jax.lax.map(train_one, (train_cameras, train_keys, train_weights))
  h_train = jax.tree.map(lambda h: jnp.einsum("v,v...->...", train_weights, h), h_views)
  inverse = jax.tree.map(lambda h: 1.0 / (h + reg), h_train)

  def score_one(camera, inv):
    h, stats = fisher_diagonal(model, camera, k_cand, num_probes=num_probes,
                               settings=settings, background=background, groups=groups)
    total = sum(jnp.sum(h[g] * inv[g]) for g in h)
    return total, stats

  values, cand_stats = map_cameras(score_one, candidates, inverse, num_devices=num_devices)
  overflow = jnp.any(train_stats.overflow) | jnp.any(cand_stats.overflow)
  num_padded = jnp.maximum(jnp.max(train_stats.num_padded), jnp.max(cand_stats.num_padded))
  return FisherScores(values, h_train, num_padded, overflow)


def fisher_scores(model, train_cameras, candidates, key, *, settings: RenderSettings,
                  background, num_probes=1, train_probes=8, reg=1e-6, groups=DEFAULT_GROUPS,
                  num_devices=1, pad_to=None, max_budget=1 << 24):
  """FisherRF scores sum_d H_d(candidate) / (H_d(train) + reg) of every candidate.

  Args:
    model: deterministic `mfsample.model.Model`.
    train_cameras: `Camera` [V] of the training views.
    candidates: `Camera` [B].
    key: PRNG key of the probes.
    settings: starting `RenderSettings` (the budget grows on overflow).
    background: [3] colour.
    num_probes: probes per candidate (one backward pass each).
    train_probes: probes per training view (H(train) sits in a denominator, where noise
      hurts more: use more).
    reg: lambda of the score (FisherRF: 1e-6).
    groups: parameter groups (FisherRF leaves out rotations).
    num_devices: devices to shard the candidates over.
    pad_to: pad the training views to this many (zero weight), so that one compilation
      serves every round of the protocol.
    max_budget: refuse to grow the budget beyond this.

  Returns:
    (`FisherScores`, settings that sufficed).
  """
  background = jnp.asarray(background, model.params.mean["means"].dtype)
  groups = tuple(g for g in groups if g in model.params.mean)
  v = train_cameras.batch_shape[0]
  slots = np.minimum(np.arange(max(v, pad_to or v)), v - 1)
  weights = jnp.asarray(np.arange(len(slots)) < v, background.dtype)
  train_cameras = train_cameras[slots]
  return render_with_budget(
      _fisher_scores, settings, model, train_cameras, weights, candidates, key, background,
      reg, num_probes=int(num_probes), train_probes=int(train_probes), groups=groups,
      num_devices=int(num_devices), max_budget=max_budget,
      stats_of=lambda out: out,  # FisherScores carries overflow and num_padded itself
      what="FisherRF scoring")


def fisher_pixel_variance_from_probes(model, camera, h_train, probes, reg, *,
                                      settings: RenderSettings, background,
                                      groups=DEFAULT_GROUPS):
  """mean_k sum_channels (J (D^(1/2) w_k))^2 per pixel over given probes w_k.

  With Rademacher probes this is an unbiased estimate of u = diag(J D J^T) summed over the
  channels; with probes whose second moment (1/K) sum_k w_k w_k^T is the identity (rows of
  a Hadamard matrix) it is u exactly.

  Args:
    probes: {group: [K, C, ...]} probe entries, one leading [K] axis on every group of the
      differentiated parameters.
    (the others as in `fisher_pixel_variance`)

  Returns:
    ([H, W], `TileStats` of the render).
  """
  diff, image = _image_fn(model, camera, background, settings, groups)
  scale = {g: jax.lax.rsqrt(h_train[g] + reg) for g in diff}

  def one(w):
    tangent = {g: scale[g] * w[g] for g in diff}
    _, d_rgb, stats = jax.jvp(image, (diff,), (tangent,), has_aux=True)
    return jnp.sum(jnp.square(d_rgb), axis=-1), stats

  # Sequential: memory of one JVP. Every probe renders the same image: one's stats suffice.
  maps, stats = jax.lax.map(one, probes)
  return jnp.mean(maps, axis=0), jax.tree.map(lambda x: x[0], stats)


@functools.partial(jax.jit, static_argnames=("settings", "num_probes", "groups"))
def fisher_pixel_variance(model, camera, h_train, key, reg, *, settings: RenderSettings,
                          background, num_probes, groups=DEFAULT_GROUPS):
  """FisherRF's per-pixel uncertainty of one camera: u(p) = sum_d D_d (dI_p / dtheta_d)^2.

  The per-pixel terms of the candidate score (module docstring), D = 1 / (H(train) + reg):
  summed over pixels, u is the camera's score, in expectation. An unbiased estimate with
  `num_probes` Rademacher probes over the parameters, one Jacobian-vector product each; per
  pixel its relative standard deviation is at most sqrt(2 / num_probes).

  Args:
    model: deterministic `mfsample.model.Model` (its mean parameters are used).
    camera: unbatched `Camera`.
    h_train: {group: [C, ...]} H accumulated over the training views
      (`FisherScores.h_train`).
    key: PRNG key of the probes.
    reg: lambda.
    settings: `RenderSettings` (static).
    background: [3] colour.
    num_probes: K (static).
    groups: parameter groups (those of `h_train`).

  Returns:
    ([H, W] estimate of u, `TileStats` of the render).
  """
  groups = tuple(g for g in groups if g in model.params.mean)
  keys = jax.random.split(key, len(groups))
  probes = {g: rademacher(k, (num_probes,) + model.params.mean[g].shape,
                          model.params.mean[g].dtype) for g, k in zip(groups, keys, strict=True)}
  return fisher_pixel_variance_from_probes(model, camera, h_train, probes, reg,
                                           settings=settings, background=background,
                                           groups=groups)
