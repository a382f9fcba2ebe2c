"""U of Eq. 10: values, gradients w.r.t. the camera, batching, chunking and sharding."""

import os
import subprocess
import sys
import textwrap

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import float64, xla_flags_with_host_devices
from planning_testlib import opposite_uv, random_model, sphere_for, tiny_pool, trained_one_view

from mfsample import RenderSettings
from mfsample import view_uncertainty as unc
from mfsample.planning import poses
from mfsample.samplers import sample_z

SETTINGS = RenderSettings(max_intersections=1 << 12)
SPHERE = poses.SphereSpec(radius=3.0, v_range=(0.05, 0.95), width=20, height=16)
UV = np.array([0.15, 0.3], np.float32)


@pytest.fixture(scope="module")
def model():
  return random_model("lowrank")


def test_pixel_variance_is_the_biased_sample_variance_summed_over_rgb():
  rgbs = np.random.default_rng(0).uniform(size=(3, 4, 5, 3))
  expected = np.mean(np.sum((rgbs - rgbs.mean(0)) ** 2, axis=-1), axis=0)
  np.testing.assert_allclose(unc.pixel_variance(jnp.asarray(rgbs)), expected, rtol=1e-5)


@pytest.mark.slow
def test_two_samples_give_quarter_squared_difference(model):
  # With M = 2, (1/2) sum_m ||C_m - C_mean||^2 = ||C_1 - C_2||^2 / 4 per pixel.
  z = sample_z(model, 2)
  cam = poses.spherical_camera(UV, SPHERE)
  out = unc.uncertainty(model, cam, z, settings=SETTINGS)
  assert not np.any(out.stats.overflow)
  g = unc.sample_gaussians(model, z)
  from mfsample import render
  r = [render(jax.tree.map(lambda x, i=i: x[i], g), cam, settings=SETTINGS).rgb for i in (0, 1)]
  expected = np.sum((np.asarray(r[0]) - np.asarray(r[1])) ** 2, axis=-1) / 4.0
  np.testing.assert_allclose(out.pixel_map, expected, rtol=1e-4, atol=1e-9)
  np.testing.assert_allclose(out.value, expected.sum(), rtol=1e-4)
  assert float(out.value) > 0.0
  assert out.pixel_map.shape == (SPHERE.height, SPHERE.width)


def test_deterministic_model_has_zero_uncertainty():
  det = random_model("deterministic")
  z = sample_z(det, 4)
  assert z.shape == (4, 0)
  out = unc.uncertainty(det, poses.spherical_camera(UV, SPHERE), z, settings=SETTINGS)
  assert float(out.value) == 0.0
  assert np.all(np.asarray(out.pixel_map) == 0.0)


def test_sobol_samples_are_the_first_scrambled_points(model):
  z = np.asarray(sample_z(model, 2, seed=6174))
  assert z.shape == (2, 2) and np.all(np.abs(z) <= 1.0)
  # The first two points of a scrambled Sobol sequence sit in opposite halves per axis.
  assert np.all(np.sign(z[0]) != np.sign(z[1]))


@pytest.mark.slow
def test_gradient_wrt_camera_matches_finite_differences():
  # dU/d(u, v) on the camera sphere and dU/dxi of a free 6-DoF motion, against central
  # differences in float64. The step is tiny on purpose: a splatted image has measure-zero
  # discontinuities in the pose (two Gaussians swapping depth order, a footprint crossing
  # its cut-off), and steps of 1e-6 .. 1e-3 cross some of them.
  with float64():
    m = random_model("lowrank", dtype=jnp.float64, num=40, b_hat=0.05, seed=3)
    z = sample_z(m, 2)
    sphere = SPHERE.replace(width=16, height=12)
    settings = RenderSettings(max_intersections=1 << 12)

    @jax.jit
    def u_of(params):
      camera = poses.perturb_camera(poses.spherical_camera(params[:2], sphere), params[2:])
      return unc.uncertainty(m, camera, z, settings=settings).value

    params = jnp.asarray([0.2, 0.35, 0, 0, 0, 0, 0, 0], jnp.float64)
    grad = np.asarray(jax.jit(jax.grad(u_of))(params))
    eps = 1e-7
    fd = np.array([(u_of(params + eps * e) - u_of(params - eps * e)) / (2 * eps)
                   for e in np.eye(8)])
    assert np.all(np.isfinite(grad)) and np.abs(grad).max() > 0
    np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-6 * np.abs(fd).max())


@pytest.mark.slow
def test_one_training_view_opposite_view_is_more_uncertain():
  pool = tiny_pool()
  trained = trained_one_view("lowrank", view=0)
  z = sample_z(trained.model, 2, seed=6174)
  sphere = sphere_for(pool)
  uv_train = poses.camera_to_uv(pool.candidates.cameras[0])
  cams = poses.spherical_camera(jnp.asarray(np.stack([uv_train, opposite_uv(uv_train)]),
                                            jnp.float32), sphere)
  scores, _ = unc.score_cameras(trained.model, cams, z, settings=trained.settings,
                                background=jnp.asarray(pool.background))
  u_train, u_opposite = np.asarray(scores.values)
  assert u_opposite > 1.5 * u_train > 0.0


@pytest.mark.slow
def test_scores_match_single_camera_calls_for_any_chunk_size(model):
  z = sample_z(model, 2)
  uv = np.random.default_rng(1).uniform([0.0, 0.1], [1.0, 0.5], (5, 2)).astype(np.float32)
  cams = poses.spherical_camera(uv, SPHERE)
  single = [float(unc.uncertainty(model, cams[i], z, settings=SETTINGS).value)
            for i in range(5)]
  for chunk in (1, 2):
    out, _ = unc.score_cameras(model, cams, z, settings=SETTINGS, chunk_size=chunk,
                               with_maps=True)
    np.testing.assert_allclose(out.values, single, rtol=1e-5)
    np.testing.assert_allclose(np.sum(out.pixel_maps, axis=(1, 2)), single, rtol=1e-5)


@pytest.mark.slow
def test_scoring_grows_the_budget_instead_of_truncating(model):
  z = sample_z(model, 2)
  cams = poses.spherical_camera(jnp.asarray([UV, UV + 0.2]), SPHERE)
  tight = RenderSettings(max_intersections=32, chunk_size=8, chunks_per_step=4)
  out, grown = unc.score_cameras(model, cams, z, settings=tight)
  assert grown.max_intersections > tight.max_intersections
  ref, _ = unc.score_cameras(model, cams, z, settings=SETTINGS)
  np.testing.assert_allclose(out.values, ref.values, rtol=1e-5)


def test_scoring_does_not_retrace(model):
  z = sample_z(model, 2)
  cams = poses.spherical_camera(jnp.asarray([UV, UV + 0.1, UV + 0.2]), SPHERE)
  counted = chex.assert_max_traces(unc.uncertainty_of_samples, n=1)
  fn = jax.jit(lambda g, c: counted(g, c, settings=SETTINGS, background=jnp.zeros(3)).value)
  g = unc.sample_gaussians(model, z)
  for i in range(3):
    fn(g, cams[i])  # new values, same shapes: one trace


_SHARDED = textwrap.dedent("""
    import jax, jax.numpy as jnp, numpy as np
    assert jax.device_count() == 4, jax.devices()
    from mfsample import RenderSettings, view_uncertainty as unc
    from mfsample.planning import poses
    from mfsample.samplers import sample_z
    from planning_testlib import random_model
    m = random_model("lowrank", num=40)
    z = sample_z(m, 2)
    sphere = poses.SphereSpec(radius=3.0, width=16, height=16)
    uv = np.random.default_rng(0).uniform([0, 0.1], [1, 0.5], (6, 2)).astype(np.float32)
    cams = poses.spherical_camera(uv, sphere)
    s = RenderSettings(max_intersections=1 << 12)
    one, _ = unc.score_cameras(m, cams, z, settings=s, num_devices=1)
    four, _ = unc.score_cameras(m, cams, z, settings=s, num_devices=4)
    np.testing.assert_allclose(np.asarray(four.values), np.asarray(one.values), rtol=1e-5)
    from mfsample.sharding import default_num_devices
    # Every split uses all devices (one mesh), padded: 6 cameras on 4 devices, 2 padded.
    assert default_num_devices(6) == 4 and default_num_devices(2) == 4
    assert default_num_devices(1) == 1
    # The M samples of one camera split over devices (M = 3 padded to 4).
    z3 = sample_z(m, 3)
    a = unc.uncertainty(m, cams[0], z3, settings=s, num_devices=1)
    b = unc.uncertainty(m, cams[0], z3, settings=s, num_devices=4)
    np.testing.assert_allclose(np.asarray(b.pixel_map), np.asarray(a.pixel_map), rtol=1e-5,
                               atol=1e-9)
    print("SHARDED_OK", np.asarray(four.values).sum())
""")


@pytest.mark.slow
def test_candidate_scoring_and_samples_shard_over_devices():
  here = os.path.dirname(os.path.dirname(__file__))  # tests/, beside the package
  env = dict(os.environ, XLA_FLAGS=xla_flags_with_host_devices(4),
             PYTHONPATH=os.pathsep.join([os.path.dirname(here), here]), JAX_PLATFORMS="cpu")
  proc = subprocess.run([sys.executable, "-c", _SHARDED], env=env, capture_output=True,
                        text=True, timeout=300)
  assert proc.returncode == 0, proc.stderr[-3000:]
  assert "SHARDED_OK" in proc.stdout
