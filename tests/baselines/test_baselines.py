"""The baselines: FisherRF's probe estimators against exact Jacobians, ACP's gains."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import float64
from planning_testlib import random_model, tiny_pool

from mfsample import RenderSettings
from mfsample.baselines import acp, fisher
from mfsample.planning import poses

# ------------------------------------------------------------------ FisherRF


def test_fisher_probe_estimator_is_unbiased():
  # A 2 x 1 image has 6 outputs. The mean of (J^T v)^2 over all 2^6 Rademacher sign vectors
  # is the exact expectation of the estimator; over the 6 unit vectors (times 6) it is
  # diag(J^T J) by definition. Both go through the same compiled function (64 probes each,
  # the unit vectors padded with zeros).
  with float64():
    m = random_model("deterministic", num=6, dtype=jnp.float64, radius=0.05, seed=1)
    sphere = poses.SphereSpec(radius=3.0, width=2, height=1, fov_x=0.05)
    cam = poses.spherical_camera(jnp.asarray([0.1, 0.3], jnp.float64), sphere)
    s = RenderSettings(max_intersections=32, chunk_size=8, chunks_per_step=4)
    bg = jnp.asarray([0.2, 0.3, 0.4])
    signs = np.array([[1.0 if (i >> b) & 1 else -1.0 for b in range(6)] for i in range(64)])
    units = np.zeros((64, 6))
    units[:6] = np.eye(6)
    fn = jax.jit(lambda p: fisher.fisher_diagonal_from_probes(
        m, cam, p.reshape(64, 1, 2, 3), settings=s, background=bg)[0])
    expectation = fn(jnp.asarray(signs))
    exact = jax.tree.map(lambda x: 64.0 * x, fn(jnp.asarray(units)))
    total = sum(float(jnp.sum(x)) for x in jax.tree.leaves(exact))
    assert total > 0.0 and set(exact) == set(fisher.DEFAULT_GROUPS) - {"sh_rest"}
    for k in exact:
      np.testing.assert_allclose(expectation[k], exact[k], rtol=1e-9, atol=1e-12 * total)


@pytest.mark.slow
def test_fisher_pixel_variance_decomposes_the_score():
  # u(p) = sum_d D_d (dI_p / dtheta_d)^2 from the full Jacobian (forward mode), against the
  # probe estimator with the 64 rows of a Hadamard matrix as probes, whose second moment is
  # exactly the identity over the 60 live parameters (6 Gaussians x 10): it must be exact.
  with float64():
    m = random_model("deterministic", num=6, dtype=jnp.float64, radius=0.05, seed=1)
    sphere = poses.SphereSpec(radius=3.0, width=3, height=2, fov_x=0.06)
    cam = poses.spherical_camera(jnp.asarray([0.1, 0.3], jnp.float64), sphere)
    s = RenderSettings(max_intersections=32, chunk_size=8, chunks_per_step=4)
    bg = jnp.asarray([0.2, 0.3, 0.4])
    groups = tuple(g for g in fisher.DEFAULT_GROUPS if g in m.params.mean)
    rng = np.random.default_rng(0)
    h_train = {g: jnp.asarray(rng.uniform(0.1, 2.0, m.params.mean[g].shape)) for g in groups}
    reg = 0.05
    diff, image = fisher._image_fn(m, cam, bg, s, groups)
    # The Jacobian w.r.t. the 6 live rows only (padding rows have none): 60 JVPs.
    rgb = lambda live: image({g: diff[g].at[:6].set(live[g]) for g in groups})[0]
    jac = jax.jacfwd(rgb)({g: diff[g][:6] for g in groups})  # {g: [H, W, 3, 6, ...]}
    exact = sum(jnp.sum(jnp.square(jac[g]) / (h_train[g][:6] + reg), axis=tuple(
        range(3, jac[g].ndim))) for g in groups).sum(axis=-1)
    hadamard = np.array([[1.0]])
    while len(hadamard) < 64:
      hadamard = np.block([[hadamard, hadamard], [hadamard, -hadamard]])
    # Padding rows (capacity 256) have no gradient: their probe entries stay 0.
    live = {g: m.params.mean[g][:6].shape for g in groups}
    sizes = [int(np.prod(shape)) for shape in live.values()]
    assert sum(sizes) == 60
    columns = np.split(hadamard[:, :60], np.cumsum(sizes)[:-1], axis=1)
    probes = {}
    for g, c in zip(groups, columns, strict=True):
      full = np.zeros((64,) + m.params.mean[g].shape)
      full[:, :6] = c.reshape((64,) + live[g])
      probes[g] = jnp.asarray(full)
    u, stats = fisher.fisher_pixel_variance_from_probes(m, cam, h_train, probes, reg,
                                                        settings=s, background=bg,
                                                        groups=groups)
    assert not bool(stats.overflow) and float(jnp.min(exact)) > 0.0
    np.testing.assert_allclose(u, exact, rtol=1e-9)
    # Summed over pixels: the score, sum_d H_d(camera) D_d with H_d = sum_p J_pd^2.
    h_cam = {g: jnp.sum(jnp.square(jac[g]), axis=(0, 1, 2)) for g in groups}
    score = sum(float(jnp.sum(h_cam[g] / (h_train[g][:6] + reg))) for g in groups)
    np.testing.assert_allclose(float(jnp.sum(u)), score, rtol=1e-9)
    # Random signs instead: the same computation, unbiased, noisier (bound sqrt(2 / K)).
    est, _ = fisher.fisher_pixel_variance(m, cam, h_train, jax.random.PRNGKey(0), reg,
                                          settings=s, background=bg, num_probes=32,
                                          groups=groups)
    np.testing.assert_allclose(est, exact, rtol=4 * np.sqrt(2 / 32))


# ------------------------------------------------------------------ ACP


def test_acp_gains_are_differences_of_the_score():
  pool = tiny_pool()
  dirs = acp.fibonacci_directions(16)
  pts = acp.grid_points(*pool.bounds, resolution=8)
  cams = pool.candidates.cameras
  obs = acp.observe(cams, pts, dirs)
  train = acp.Observations(obs.visible[:2], obs.bins[:2])
  gains = acp.acp_gains(train, obs, 16, weight=0.5)
  for c in (2, 5):
    both = acp.Observations(obs.visible[[0, 1, c]], obs.bins[[0, 1, c]])
    assert gains[c] == pytest.approx(acp.acp_value(both, 16, 0.5) - acp.acp_value(train, 16,
                                                                                     0.5))
  assert gains[0] == pytest.approx(0.0)  # a training camera adds nothing


def test_activenerf_renders_the_variance_of_its_gaussians_blended_like_colours():
  """beta^2(p) = beta_min + sum_i w_i exp(s_i): with one log-variance s for every Gaussian,
  beta_min + exp(s) x the pixel's opacity."""
  from render_testlib import SMALL as settings

  from mfsample import orbit_camera, render
  from mfsample.baselines.activenerf import rendered_variance
  from mfsample.testing import random_gaussians

  gaussians = random_gaussians(12, sh_degree=0, seed=4)
  cam = orbit_camera(0.3, 0.4, width=8, height=8, distance=4.0)
  beta2, stats = rendered_variance(gaussians, jnp.full((12,), jnp.log(0.5)), cam, 0.01,
                                   settings=settings)
  alpha = render(gaussians, cam, settings=settings).alpha
  np.testing.assert_allclose(beta2, 0.01 + 0.5 * alpha, atol=1e-6)
  assert not bool(stats.overflow) and float(jnp.max(alpha)) > 0.05
