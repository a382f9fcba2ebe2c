"""Uncertainty per Gaussian: the gradient trick against explicit blending weights, the
identity sum_g share_g = sum_v sum_p (1 - T_final) var_v <= U, and the spreads of B_hat
against Monte Carlo."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from planning_testlib import BOUNDS

from mfsample import RenderSettings, render
from mfsample import view_uncertainty as unc
from mfsample.camera import Camera
from mfsample.gaussian_uncertainty import (
  GaussianUncertainty,
  gaussian_uncertainty,
  spreads,
  view_share,
)
from mfsample.groups import GROUPS
from mfsample.model import init_model, mean_gaussians, sample
from mfsample.samplers import SamplerSpec, sample_z

SETTINGS = RenderSettings(max_intersections=1 << 10)
SIZE = 16


def small_model(kind="lowrank", groups=GROUPS, num=24, capacity=32, seed=0):
  """`num` live Gaussians in a capacity of 32 (8 padding rows), B_hat large enough for U > 0."""
  rng = np.random.default_rng(seed)
  spec = SamplerSpec(kind=kind, rank=2, groups=groups if kind != "deterministic" else (),
                     bounds=BOUNDS)
  return init_model(jax.random.PRNGKey(seed), rng.uniform(-0.5, 0.5, (num, 3)), spec=spec,
                    sh_degree=0, init_scales={g: 0.08 for g in GROUPS}, capacity=capacity,
                    init_opacity=0.7, colors=rng.uniform(0.1, 0.9, (num, 3)))


def cameras(num=2):
  eyes = np.array([[2.5, 0.4, 0.8], [-0.6, 2.4, 1.0], [0.3, -2.2, -1.2]])[:num]
  return Camera.look_at(jnp.asarray(eyes, jnp.float32), jnp.zeros((num, 3)),
                        jnp.array([0.0, 0.0, 1.0]), 1.0, SIZE, SIZE)


@pytest.fixture(scope="module")
def model():
  return small_model()


@pytest.fixture(scope="module")
def z(model):
  return sample_z(model, 4)


WHITE = jnp.array([1.0, 1.0, 1.0])


@pytest.fixture(scope="module")
def three_views(model, z):
  return gaussian_uncertainty(model, cameras(3), z, settings=SETTINGS, background=WHITE)


@pytest.mark.slow
def test_share_is_the_variance_weighted_by_explicit_blending_weights(model, z):
  """The gradient trick against the weights themselves: rendering one-hot features (one
  channel per Gaussian) blends w_g(p) into channel g."""
  camera = cameras(1)[0]
  bg = jnp.array([0.2, 0.3, 0.4])
  share, variance, stats = view_share(model, camera, z, bg, settings=SETTINGS)
  assert not np.any(stats.overflow) and stats.overflow.shape == (5,)  # M samples + the mean
  np.testing.assert_allclose(variance, unc.uncertainty(model, camera, z, settings=SETTINGS,
                                                       background=bg).pixel_map, rtol=1e-5)
  onehot = jnp.eye(model.capacity, dtype=jnp.float32)
  weights = render(mean_gaussians(model), camera, settings=SETTINGS, features=onehot).rgb
  expected = np.einsum("hwg,hw->g", np.asarray(weights, np.float64),
                       np.asarray(variance, np.float64))
  assert expected.max() > 0
  np.testing.assert_allclose(share, expected, rtol=1e-4, atol=1e-7 * expected.max())
  assert np.all(np.asarray(share)[24:] == 0.0)  # padding rows


@pytest.mark.slow
def test_shares_split_u_over_the_opaque_part_of_the_views(model, z, three_views):
  """sum_g share_g = sum_v sum_p (1 - T_final^v(p)) var_v(p) <= sum_v U_v."""
  bg = WHITE
  cams = cameras(3)
  out = three_views
  assert isinstance(out, GaussianUncertainty)
  assert all(np.asarray(f).shape == (32,) and np.asarray(f).dtype == np.float32 for f in out)
  opaque_variance, total_u = 0.0, 0.0
  for i in range(3):
    u = unc.uncertainty(model, cams[i], z, settings=SETTINGS, background=bg)
    alpha = render(mean_gaussians(model), cams[i], settings=SETTINGS).alpha
    opaque_variance += float(np.sum(np.asarray(alpha, np.float64) * np.asarray(u.pixel_map)))
    total_u += float(u.value)
  assert 0.0 < opaque_variance < total_u
  np.testing.assert_allclose(np.sum(out.share, dtype=np.float64), opaque_variance, rtol=1e-4)
  assert np.all(out.share >= 0.0)
  one = gaussian_uncertainty(model, cams[0], z, settings=SETTINGS, background=bg)
  assert 0.0 < one.share.sum() < out.share.sum()  # an unbatched camera is one view


@pytest.mark.slow
def test_spreads_match_monte_carlo_over_z(model, three_views):
  """position_std and colour_std are the standard deviations of the centre and the DC colour
  (0.5 + SH_C0 f_dc) over theta(z), z ~ U[-1, 1]^k."""
  out = three_views
  zs = jax.random.uniform(jax.random.PRNGKey(1), (20_000, 2), minval=-1.0, maxval=1.0)
  g = jax.vmap(lambda zi: sample(model, zi))(zs)
  live = np.asarray(model.mask)
  means = np.asarray(g.means, np.float64)[:, live]
  colour = 0.5 + 0.28209479177387814 * np.asarray(g.sh, np.float64)[:, live, 0]
  np.testing.assert_allclose(out.position_std[live], np.sqrt(means.var(0).sum(-1)), rtol=0.03)
  np.testing.assert_allclose(out.colour_std[live], np.sqrt(colour.var(0).sum(-1)), rtol=0.03)
  assert np.all(out.position_std[~live] == 0.0) and np.all(out.colour_std[~live] == 0.0)
  assert out.position_std[live].min() > 0.0


@pytest.mark.slow
def test_deterministic_groups_and_models_have_zero_spread_and_share():
  position_std, colour_std = spreads(small_model(groups=("sh_dc",)))
  assert np.all(np.asarray(position_std) == 0.0) and float(colour_std.max()) > 0.0
  det = small_model("deterministic")
  out = gaussian_uncertainty(det, cameras(2), sample_z(det, 2), settings=SETTINGS)
  assert all(np.all(np.asarray(f) == 0.0) for f in out)


@pytest.mark.slow
def test_budget_grows_instead_of_truncating(model, z):
  tight = RenderSettings(max_intersections=32, chunks_per_step=1, tile_size=8)
  assert np.any(view_share(model, cameras(1)[0], z, jnp.zeros(3), settings=tight)[2].overflow)
  grown = gaussian_uncertainty(model, cameras(1), z, settings=tight)
  np.testing.assert_allclose(grown.share, gaussian_uncertainty(
      model, cameras(1), z, settings=SETTINGS).share, rtol=1e-4, atol=1e-9)
  with pytest.raises(TypeError, match="mfsample.Camera"):
    gaussian_uncertainty(model, np.eye(4), z, settings=SETTINGS)
