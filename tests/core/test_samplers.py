"""Tests of mfsample.samplers: statistics of theta(z), z sources, extremes."""

import dataclasses
import json

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mfsample import samplers
from mfsample.groups import GROUPS
from mfsample.model import init_model, mean_gaussians, sample
from mfsample.samplers import SamplerSpec

BOUNDS = (("means", 4.0), ("log_scales", 20.0), ("quats", 2.0), ("opacity_logits", 20.0),
          ("sh_dc", 0.5), ("sh_rest", 0.5))
KINDS = ("deterministic", "diagonal", "block", "lowrank")


def _model(kind, rank=2, n=6, sh_degree=1, scale=0.05, capacity=8, groups=GROUPS, seed=0):
  spec = SamplerSpec(kind=kind, rank=rank, groups=groups, bounds=BOUNDS)
  pts = np.random.default_rng(seed).uniform(-1, 1, (n, 3))
  return init_model(jax.random.PRNGKey(seed), pts, spec=spec, sh_degree=sh_degree,
                    init_scales={g: scale for g in GROUPS}, capacity=capacity)


def _uniform_z(model, num, key):
  """M pseudo-random z's on [-1, 1] for `model`, whatever its z source (statistics)."""
  return jax.random.uniform(key, (num,) + samplers.z_shape(model), minval=-1.0, maxval=1.0)


def _flat(tree):
  return jnp.concatenate([jnp.ravel(tree[g]) for g in sorted(tree)])


@pytest.mark.parametrize("kind", KINDS)
def test_z_shape_and_sample_under_vmap(kind):
  model = _model(kind, rank=3)
  m = 4
  z = _uniform_z(model, m, jax.random.PRNGKey(1))
  assert z.shape == (m,) + samplers.z_shape(model)
  batch = jax.jit(jax.vmap(sample, in_axes=(None, 0)))(model, z)
  assert batch.means.shape == (m, model.capacity, 3)
  assert batch.sh.shape == (m, model.capacity, 4, 3)
  np.testing.assert_array_equal(batch.mask[0], model.mask)


def test_expected_z_shapes():
  assert samplers.z_shape(_model("deterministic")) == (0,)
  assert samplers.z_shape(_model("lowrank", rank=5)) == (5,)
  model = _model("block", rank=3)
  assert samplers.z_shape(model) == (model.capacity, 3)
  # diagonal: one z per stochastic entry of a Gaussian (3 + 3 + 4 + 1 + 3 + 9 at degree 1)
  assert samplers.z_shape(_model("diagonal")) == (model.capacity, 23)
  assert samplers.z_shape(_model("diagonal", groups=("means", "sh_dc"))) == (model.capacity, 6)


def test_deterministic_sample_is_the_mean():
  model = _model("deterministic")
  g = sample(model, jnp.zeros((0,)))
  chex.assert_trees_all_equal(g, mean_gaussians(model))


@pytest.mark.parametrize("kind", ("diagonal", "block", "lowrank"))
def test_zero_z_gives_the_mean(kind):
  model = _model(kind)
  z = jnp.zeros(samplers.z_shape(model))
  chex.assert_trees_all_close(jax.jit(samplers.perturb)(model, z), model.params.mean)


@pytest.mark.parametrize("kind", ("diagonal", "block", "lowrank"))
def test_sample_statistics_match_closed_form(kind):
  """Mean of many samples -> mean model; per-entry variance -> sum_j B_hat_j^2 / 3."""
  model = _model(kind, rank=3, scale=0.2)
  num = 50_000
  if kind == "lowrank":
    z = jnp.asarray(samplers.sobol_z(num, 3, seed=7))
  else:
    z = _uniform_z(model, num, jax.random.PRNGKey(3))
  thetas = jax.jit(jax.vmap(lambda zi: _flat(samplers.perturb(model, zi))))(z)
  mean = _flat(model.params.mean)
  var = _flat({g: v for g, v in samplers.entry_variance(model).items()}
              | {g: jnp.zeros_like(v) for g, v in model.params.mean.items()
                 if g not in model.params.b_hat})
  live = np.concatenate([np.repeat(np.asarray(model.mask), np.prod(v.shape[1:]))
                         for _, v in sorted(model.params.mean.items())])
  emp_mean = np.asarray(jnp.mean(thetas, axis=0))
  emp_var = np.asarray(jnp.var(thetas, axis=0))
  scale = float(np.sqrt(np.max(np.asarray(var))))
  # Monte Carlo error of the mean ~ sigma / sqrt(num) (Sobol: much less).
  np.testing.assert_allclose(emp_mean[live], np.asarray(mean)[live], atol=5 * scale / num**0.5)
  np.testing.assert_allclose(emp_var[live], np.asarray(var)[live], rtol=0.05, atol=1e-7)
  # Padding rows never move.
  np.testing.assert_array_equal(emp_var[~live], 0.0)


def test_lowrank_samples_lie_on_a_k_dimensional_manifold():
  model = _model("lowrank", rank=2, scale=0.3)
  z = _uniform_z(model, 50, jax.random.PRNGKey(0))
  thetas = jax.jit(jax.vmap(lambda zi: _flat(samplers.perturb(model, zi))))(z)
  s = np.linalg.svd(np.asarray(thetas - _flat(model.params.mean)), compute_uv=False)
  assert s[1] > 1e-3 * s[0] and s[2] < 1e-5 * s[0]  # rank exactly 2


def test_block_samples_are_independent_across_gaussians():
  model = _model("block", rank=2, n=2, scale=0.3, capacity=2, groups=("means",))
  z = _uniform_z(model, 20_000, jax.random.PRNGKey(4))
  x = np.asarray(jax.jit(jax.vmap(lambda zi: samplers.perturb(model, zi)["means"]))(z))
  corr = np.corrcoef(x[:, 0, 0], x[:, 1, 0])[0, 1]
  within = np.corrcoef(x[:, 0, 0], x[:, 0, 1])[0, 1]
  assert abs(corr) < 0.05 and abs(within) > 0.05


def test_sobol_z_is_deterministic_in_range_and_resumable():
  a = samplers.sobol_z(64, 3, seed=11)
  assert a.shape == (64, 3) and a.dtype == np.float32
  assert a.min() >= -1.0 and a.max() <= 1.0
  np.testing.assert_array_equal(a, samplers.sobol_z(64, 3, seed=11))
  np.testing.assert_array_equal(a[40:], samplers.sobol_z(24, 3, seed=11, offset=40))
  assert not np.array_equal(a, samplers.sobol_z(64, 3, seed=12))
  # Low discrepancy: the mean of 64 points is far closer to 0 than for random points.
  assert np.abs(a.mean(0)).max() < 0.02
  assert samplers.sobol_z(5, 0, seed=0).shape == (5, 0)


def test_the_spec_decides_the_z_source():
  """sample_z: Sobol points for the low-rank sampler (its default), uniforms otherwise; the
  step's draw_z takes the Sobol rows where the source is Sobol, the key's uniforms elsewhere."""
  lowrank = _model("lowrank", rank=2)
  assert lowrank.spec.z_source == "sobol"
  np.testing.assert_array_equal(samplers.sample_z(lowrank, 3, seed=5),
                                samplers.sobol_z(3, 2, seed=5))
  rows = samplers.sobol_z(3, 2, seed=0)
  np.testing.assert_array_equal(samplers.draw_z(lowrank, 3, jax.random.PRNGKey(0), rows), rows)
  for model in (_model("lowrank", rank=2).replace(spec=dataclasses.replace(lowrank.spec,
                                                                           z="uniform")),
                _model("block", rank=2), _model("diagonal")):
    assert model.spec.z_source == "uniform"
    z = samplers.sample_z(model, 1000, seed=3)
    assert z.shape == (1000,) + samplers.z_shape(model)
    assert -1.0 <= float(z.min()) and float(z.max()) <= 1.0 and float(z.std()) > 0.5
    np.testing.assert_array_equal(
        samplers.draw_z(model, 4, jax.random.PRNGKey(3), np.zeros((4, 0))),
        jax.random.uniform(jax.random.PRNGKey(3), (4,) + samplers.z_shape(model),
                           minval=-1.0, maxval=1.0))
  deterministic = _model("deterministic")
  assert deterministic.spec.z_source == "none"
  assert samplers.sample_z(deterministic, 2).shape == (2, 0)


@pytest.mark.parametrize("kind", KINDS)
def test_kinds_are_behaviour_of_the_spec(kind):
  """What a kind is (z shape, rank axis, per-Gaussian z) comes from its `SamplerKind`, and a
  spec survives its record (checkpoints, exported records)."""
  model = _model(kind, rank=3)
  spec = model.spec
  behaviour = samplers.KINDS[kind]
  assert spec.behaviour is behaviour
  assert spec.columns == ((3,) if behaviour.rank_axis else ())
  assert samplers.z_shape(model)[:1] == ((model.capacity,) if behaviour.z_per_gaussian
                                         else samplers.z_shape(model)[:1])
  for g, b in model.params.b_hat.items():
    assert b.shape[-1:] == spec.columns or not spec.columns, g
  assert SamplerSpec.from_dict(json.loads(json.dumps(spec.to_dict()))) == spec


def test_wrong_z_shape_raises():
  with pytest.raises(ValueError, match="z must have shape"):
    samplers.perturb(_model("lowrank", rank=2), jnp.zeros((3,)))


@pytest.mark.parametrize("kind,rank,n", [("lowrank", 1, 1), ("lowrank", 64, 1),
                                         ("lowrank", 64, 3), ("block", 1, 1),
                                         ("block", 64, 2), ("diagonal", 1, 1)])
def test_finite_values_and_gradients_at_the_extremes(kind, rank, n):
  """B_hat at its bounds, z at the corners, rank 1 and 64, a single Gaussian."""
  model = _model(kind, rank=rank, n=n, capacity=n)
  bounds = dict(BOUNDS)
  at_bounds = {g: jnp.full_like(v, bounds[g]) for g, v in model.params.b_hat.items()}
  model = model.replace(params=model.params._replace(b_hat=at_bounds))

  def f(params, z):
    g = sample(model.replace(params=params), z)
    return sum(jnp.sum(x) for x in (g.means, g.scales, g.quats, g.opacities, g.sh))

  sample_jit = jax.jit(sample)
  grad = jax.jit(jax.grad(f, argnums=(0, 1)))
  for corner in (-1.0, 1.0):
    z = jnp.full(samplers.z_shape(model), corner)
    chex.assert_tree_all_finite(sample_jit(model, z))
    chex.assert_tree_all_finite(grad(model.params, z))
