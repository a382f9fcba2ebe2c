"""Tests of mfsample.model: parameter groups, capacity, the one activation, B_hat."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mfsample import Gaussians
from mfsample.groups import GROUPS
from mfsample.model import (
    activate,
    capacity_bucket,
    group_shapes,
    init_b_hat,
    init_model,
    knn_scale,
    mean_gaussians,
)
from mfsample.samplers import SamplerSpec, b_hat_magnitude, clamp_b_hat, signed_b_hat

BOUNDS = (("means", 4.0), ("log_scales", 20.0), ("quats", 2.0), ("opacity_logits", 20.0),
          ("sh_dc", 0.5), ("sh_rest", 0.5))
SCALES = {g: 1e-3 for g in GROUPS}


def _spec(kind="lowrank", rank=2, groups=GROUPS):
  return SamplerSpec(kind=kind, rank=rank, groups=groups, bounds=BOUNDS)


def _points(n, seed=0):
  return np.random.default_rng(seed).uniform(-1, 1, (n, 3))


def test_group_shapes_have_no_sh_rest_at_degree_0():
  assert "sh_rest" not in group_shapes(0)
  assert group_shapes(3)["sh_rest"] == (15, 3)
  per_gaussian = sum(int(np.prod(s)) for s in group_shapes(3).values())
  assert per_gaussian == 59  # 59 channels per Gaussian at SH degree 3


def test_init_model_shapes_and_mask():
  model = init_model(jax.random.PRNGKey(0), _points(100), spec=_spec(rank=3), sh_degree=2,
                     init_scales=SCALES)
  assert model.capacity == capacity_bucket(100) == 256
  assert model.num_live == 100 and model.max_sh_degree == 2
  assert model.params.mean["sh_rest"].shape == (256, 8, 3)
  assert model.params.b_hat["means"].shape == (256, 3, 3)
  assert model.params.b_hat["opacity_logits"].shape == (256, 3)
  assert model.signs["sh_rest"].dtype == jnp.int8
  assert set(np.unique(np.asarray(model.signs["means"])[:100])) <= {-1, 1}
  # Padding rows carry no B_hat and never enter a render.
  assert not np.any(np.asarray(model.params.b_hat["means"])[100:])
  g = mean_gaussians(model)
  g.validate()
  np.testing.assert_allclose(np.asarray(g.opacities)[:100], 0.1, rtol=1e-5)


def test_degree_0_model_has_no_sh_rest_anywhere():
  model = init_model(jax.random.PRNGKey(0), _points(10), spec=_spec(), sh_degree=0,
                     init_scales=SCALES)
  assert "sh_rest" not in model.params.mean and "sh_rest" not in model.params.b_hat
  assert mean_gaussians(model).sh.shape == (model.capacity, 1, 3)


def test_deterministic_model_has_no_spread():
  model = init_model(jax.random.PRNGKey(0), _points(10), spec=_spec("deterministic"),
                     sh_degree=1, init_scales=SCALES)
  assert model.params.b_hat == {} and model.signs == {}


def test_capacity_buckets_are_power_of_two_ish_and_monotonic():
  sizes = [capacity_bucket(n) for n in range(1, 5000, 37)]
  assert sizes == sorted(sizes)
  for s in set(sizes):
    assert s & (s - 1) == 0 or (s % 3 == 0 and (s // 3) & (s // 3 - 1) == 0)
  assert capacity_bucket(257) == 384 and capacity_bucket(385) == 512


def test_activate_applies_constraints_in_one_place():
  mean = {"means": jnp.zeros((2, 3)), "log_scales": jnp.log(jnp.array([[0.1] * 3, [2.0] * 3])),
          "quats": jnp.array([[2.0, 0, 0, 0], [0, 0, 0, 0]]),
          "opacity_logits": jnp.array([0.0, 100.0]), "sh_dc": jnp.ones((2, 3)),
          "sh_rest": jnp.ones((2, 15, 3))}
  g = activate(mean, jnp.array([True, False]), 1)
  assert isinstance(g, Gaussians)
  np.testing.assert_allclose(g.scales[:, 0], [0.1, 2.0], rtol=1e-6)
  np.testing.assert_allclose(g.opacities, [0.5, 1.0])
  # SH schedule: degree 1 keeps bands 0-1 (4 coefficients) and zeroes the rest.
  assert np.all(np.asarray(g.sh[:, :4]) == 1.0) and np.all(np.asarray(g.sh[:, 4:]) == 0.0)
  assert g.mask.tolist() == [True, False]


def test_generator_is_relu_times_sign_and_projection_bounds():
  spread = {"sh_dc": jnp.array([[-1.0, 0.0, 0.3, 7.0]])}
  signs = {"sh_dc": jnp.array([[1, -1, -1, 1]], jnp.int8)}
  np.testing.assert_allclose(signed_b_hat(spread, signs)["sh_dc"], [[0.0, 0.0, -0.3, 7.0]])
  spec = _spec(groups=("sh_dc",))
  np.testing.assert_allclose(clamp_b_hat(spread, spec)["sh_dc"], [[0.0, 0.0, 0.3, 0.5]])
  # The relu passes gradient at exactly 0, so the volume term can revive a parked entry.
  grad = jax.grad(lambda s: jnp.sum(b_hat_magnitude({"sh_dc": s})["sh_dc"]))(spread["sh_dc"])
  np.testing.assert_allclose(grad, [[0.0, 1.0, 1.0, 1.0]])


def test_init_spread_scales_and_signs():
  shapes = group_shapes(0)
  scales = dict(SCALES, means=5e-3)
  spread, signs = init_b_hat(np.random.default_rng(1), 1000, shapes,
                              _spec(rank=2, groups=("means", "sh_dc")), scales)
  assert set(spread) == {"means", "sh_dc"}
  assert spread["means"].shape == (1000, 3, 2)
  assert 0.0 <= float(spread["means"].min()) and float(spread["means"].max()) <= 5e-3
  assert abs(float(np.mean(np.asarray(signs["sh_dc"])))) < 0.1  # balanced signs


def test_knn_scale_matches_brute_force():
  pts = _points(50, seed=3)
  d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
  d[np.arange(50), np.arange(50)] = np.inf
  ref = np.sqrt(np.mean(np.sort(d, axis=1)[:, :3] ** 2, axis=1))
  np.testing.assert_allclose(knn_scale(pts), ref, rtol=1e-6)
  assert knn_scale(pts[:1]).shape == (1,)  # one point: a finite default


@pytest.mark.parametrize("n", [1, 2])
def test_activation_finite_at_extremes(n):
  """Finite Gaussians and gradients for huge / tiny raw values and one Gaussian."""
  model = init_model(jax.random.PRNGKey(0), _points(n), spec=_spec(), sh_degree=1,
                     init_scales=SCALES, capacity=n)
  def f(mean):
    g = activate(mean, model.mask, jnp.int32(1))
    return sum(jnp.sum(x) for x in (g.scales, g.opacities, g.sh, g.means))

  act, grad = jax.jit(activate), jax.jit(jax.grad(f))
  for value in (-1e3, 0.0, 1e3):  # log-scales of +-1000 included: the clamp keeps exp finite
    mean = {g: jnp.full_like(v, value) for g, v in model.params.mean.items()}
    chex.assert_tree_all_finite(act(mean, model.mask, jnp.int32(1)))
    chex.assert_tree_all_finite(grad(mean))


def test_spec_validation():
  with pytest.raises(ValueError):
    SamplerSpec(kind="full", groups=(), bounds=())
  with pytest.raises(ValueError):
    SamplerSpec(kind="lowrank", rank=0, groups=("means",), bounds=(("means", 1.0),))
  with pytest.raises(ValueError):
    SamplerSpec(kind="lowrank", groups=("colour",), bounds=())
  with pytest.raises(ValueError):
    SamplerSpec(kind="lowrank", groups=("means",), bounds=())
  with pytest.raises(ValueError):
    init_model(jax.random.PRNGKey(0), np.zeros((3, 2)), spec=_spec(), sh_degree=0,
               init_scales=SCALES)
