"""EWA projection: rotations, covariances, the perspective Jacobian, culling."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mfsample import RenderSettings, orbit_camera
from mfsample.renderer.projection import (
  covariance_3d,
  footprint_sigma,
  project_gaussians,
  quat_to_rotmat,
)
from mfsample.testing import random_gaussians

SETTINGS = RenderSettings()


def test_quaternion_rotation_matches_scipy_and_ignores_norm():
  q = np.random.default_rng(0).normal(size=(10, 4))
  got = np.asarray(quat_to_rotmat(jnp.asarray(3.0 * q)))
  want = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()  # scipy: (x, y, z, w)
  np.testing.assert_allclose(got, want, atol=1e-5)


def test_zero_quaternion_is_identity_with_finite_gradient():
  np.testing.assert_allclose(quat_to_rotmat(jnp.zeros(4)), np.eye(3))
  grad = jax.grad(lambda q: jnp.sum(quat_to_rotmat(q) ** 3))(jnp.zeros(4))
  assert np.all(np.isfinite(grad))


def test_covariance_is_r_s2_rt():
  g = random_gaussians(5, seed=1)
  cov = np.asarray(covariance_3d(g.scales, g.quats))
  rot = np.asarray(quat_to_rotmat(g.quats))
  want = rot @ (np.eye(3) * np.asarray(g.scales)[:, None, :] ** 2) @ rot.transpose(0, 2, 1)
  np.testing.assert_allclose(cov, want, rtol=1e-5, atol=1e-9)


@pytest.mark.slow
def test_conic_inverts_the_jacobian_projected_covariance():
  """Sigma_2d = J W Sigma W^T J^T + eps I, with J from autodiff of the pinhole map."""
  g = random_gaussians(20, seed=2, extent=0.5, scale_range=(0.05, 0.2))
  cam = orbit_camera(0.3, 0.4, width=64, height=48, distance=3.0)
  proj = project_gaussians(g.means, g.scales, g.quats, g.opacities, None, cam, SETTINGS)
  assert bool(jnp.all(proj.valid))

  def pixel(p):
    uv, _ = cam.project(p[None])
    return uv[0]

  uv, z = cam.project(g.means)
  np.testing.assert_allclose(proj.means2d, uv, atol=1e-3)
  np.testing.assert_allclose(proj.depths, z, rtol=1e-6)
  cov3 = np.asarray(covariance_3d(g.scales, g.quats))
  for i in range(20):
    jac = np.asarray(jax.jacfwd(pixel)(g.means[i]))  # d(u, v)/d(world point): J W
    cov2 = jac @ cov3[i] @ jac.T + SETTINGS.eps2d * np.eye(2)
    a, b, c = np.asarray(proj.conics[i])
    np.testing.assert_allclose(np.array([[a, b], [b, c]]) @ cov2, np.eye(2), atol=2e-4)
    # The footprint: r(o) = min(3.33, sqrt(2 ln(255 o))) standard deviations.
    lam = np.linalg.eigvalsh(cov2).max()
    sigmas = min(SETTINGS.radius_sigma, np.sqrt(2 * np.log(float(g.opacities[i]) * 255)))
    np.testing.assert_allclose(proj.radii[i], sigmas * np.sqrt(lam), rtol=1e-4)


def test_footprint_radius_is_where_alpha_reaches_alpha_min():
  o = jnp.array([1.0, 0.5, 0.1, 0.02, 1.0 / 255, 0.0])
  r = np.asarray(footprint_sigma(o, SETTINGS))
  alpha_at_r = np.asarray(o) * np.exp(-0.5 * r**2)
  # With the default cap 3.33 > sqrt(2 ln 255) the alpha rule binds for every o <= 1: the
  # alpha at the radius is alpha_min. The old 3-sigma rule is the cap 3.0.
  np.testing.assert_allclose(alpha_at_r[:5], 1 / 255, rtol=1e-5)
  np.testing.assert_allclose(r[0], np.sqrt(2 * np.log(255)), rtol=1e-6)
  assert r[-1] == 0.0
  old = np.asarray(footprint_sigma(o, SETTINGS.replace(radius_sigma=3.0)))
  np.testing.assert_allclose(old, np.minimum(r, 3.0), rtol=1e-6)
  no_alpha_cut = np.asarray(footprint_sigma(o, SETTINGS.replace(alpha_min=0.0)))
  np.testing.assert_allclose(no_alpha_cut, 3.33, rtol=1e-7)


def test_culling():
  cam = orbit_camera(0.3, 0.4, width=32, height=32, distance=3.0)
  center, fwd, right = (np.asarray(cam.center), np.asarray(cam.rotation)[2],
                        np.asarray(cam.rotation)[0])
  means = np.stack([
      center + 2.0 * fwd,  # visible
      center - 1.0 * fwd,  # behind
      center + 0.1 * fwd,  # in front of the camera, closer than the near plane (0.2)
      center + 2.0 * fwd + 50.0 * right,  # off screen
      center + 2.0 * fwd,  # masked out
      center + 2.0 * fwd,  # opacity below alpha_min
  ])
  n = len(means)
  proj = project_gaussians(jnp.asarray(means, jnp.float32), jnp.full((n, 3), 0.05),
                           jnp.tile(jnp.array([1.0, 0, 0, 0]), (n, 1)),
                           jnp.array([0.5, 0.5, 0.5, 0.5, 0.5, 0.001]),
                           jnp.array([True, True, True, True, False, True]), cam, SETTINGS)
  np.testing.assert_array_equal(proj.valid, [True, False, False, False, False, False])
  np.testing.assert_array_equal(np.asarray(proj.radii)[1:], 0.0)
  assert np.all(np.isfinite(np.asarray(proj.conics)))
