"""The tiled renderer against the dense reference, gradients, extremes, jit/vmap behaviour."""

import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mfsample import Camera, Gaussians, RenderSettings, render
from mfsample._pytree import replace
from mfsample.renderer.reference import render_reference
from mfsample.testing import orbit_camera, random_gaussians

# Small chunks and steps so that one tile's list spans many chunks and several loop steps.
SMALL = RenderSettings(max_intersections=4096, chunk_size=8, chunks_per_step=4)
WIDTH, HEIGHT = 45, 31  # non-square, not a multiple of the tile size


def hard_scene(sh_degree, seed=0, num_random=60):
  """Random Gaussians plus the awkward cases, seen from `hard_camera()`."""
  g = random_gaussians(num_random, sh_degree=sh_degree, seed=seed, scale_range=(0.02, 0.3))
  cam = hard_camera()
  center, rot = np.asarray(cam.center), np.asarray(cam.rotation)
  fwd, right = rot[2], rot[0]

  def at_depth(z, side=0.0):
    return center + z * fwd + side * right

  special = [  # (mean, scales, opacity)
      (at_depth(-1.0), (0.3, 0.3, 0.3), 0.9),  # behind the camera
      (at_depth(0.25), (0.4, 0.4, 0.4), 0.8),  # straddles the near plane (0.2)
      (at_depth(3.0, side=40.0), (0.5, 0.5, 0.5), 0.9),  # far off screen
      (at_depth(3.0, side=0.3), (1e-4, 1e-4, 0.6), 0.9),  # needle-thin
      (at_depth(6.0), (4.0, 4.0, 4.0), 0.3),  # huge, behind everything
      (at_depth(2.5, side=-0.2), (0.2, 0.2, 0.2), 0.003),  # below alpha_min: invisible
      (at_depth(2.6, side=0.1), (0.2, 0.2, 0.2), 0.02),  # nearly transparent, visible
  ]
  rng = np.random.default_rng(seed + 1)
  k = (sh_degree + 1) ** 2
  extra = Gaussians(
      means=jnp.asarray(np.stack([s[0] for s in special]), jnp.float32),
      scales=jnp.asarray(np.array([s[1] for s in special]), jnp.float32),
      quats=jnp.asarray(rng.normal(size=(len(special), 4)), jnp.float32),
      opacities=jnp.asarray([s[2] for s in special], jnp.float32),
      sh=jnp.asarray(rng.normal(0, 0.3, (len(special), k, 3)), jnp.float32),
  )
  return jax.tree.map(lambda a, b: jnp.concatenate([a, b]), g, extra), cam


def hard_camera():
  return orbit_camera(WIDTH, HEIGHT, azimuth=0.7, elevation=0.3, distance=2.6, fov_x=1.1)


BACKGROUND = jnp.array([0.2, 0.5, 0.9])


@functools.partial(jax.jit, static_argnames=("settings", "reference"))
def _render_and_grads(gaussians, camera, weights, *, settings, reference=False):
  """Outputs and gradients of a random linear functional of (rgb, alpha, depth)."""

  def outputs(g, c):
    if reference:
      return render_reference(g, c, background=BACKGROUND, settings=settings)
    out = render(g, c, background=BACKGROUND, settings=settings)
    return out.rgb, out.alpha, out.depth

  def loss(g, c):
    rgb, alpha, depth = outputs(g, c)
    return (jnp.sum(weights[..., :3] * rgb) + jnp.sum(weights[..., 3] * alpha)
            + 0.1 * jnp.sum(weights[..., 4] * depth))

  grads = jax.grad(loss, argnums=(0, 1))(gaussians, camera)
  return outputs(gaussians, camera), grads


def _loss_weights(seed=3):
  return jnp.asarray(np.random.default_rng(seed).normal(size=(HEIGHT, WIDTH, 5)), jnp.float32)


def _assert_grads_close(got, want, rtol=2e-3):
  for path, g, w in zip(jax.tree_util.tree_leaves_with_path(got),
                        jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
    scale = float(np.max(np.abs(w))) + 1e-12
    np.testing.assert_allclose(np.asarray(g), np.asarray(w), rtol=rtol, atol=rtol * scale,
                               err_msg=jax.tree_util.keystr(path[0]))


@pytest.mark.parametrize("sh_degree, settings", [(3, SMALL), (0, RenderSettings())],
                         ids=["sh3-small-chunks", "sh0-default-settings"])
def test_tiled_matches_dense_reference(sh_degree, settings):
  gaussians, cam = hard_scene(sh_degree)
  weights = _loss_weights()
  (rgb, alpha, depth), grads = _render_and_grads(gaussians, cam, weights, settings=settings)
  (rgb_r, alpha_r, depth_r), grads_r = _render_and_grads(gaussians, cam, weights,
                                                         settings=settings, reference=True)
  assert rgb.shape == (HEIGHT, WIDTH, 3)
  np.testing.assert_allclose(rgb, rgb_r, atol=2e-5)
  np.testing.assert_allclose(alpha, alpha_r, atol=2e-5)
  np.testing.assert_allclose(depth, depth_r, atol=2e-4)
  assert float(alpha.max()) > 0.5, "the scene should cover part of the image"
  _assert_grads_close(grads, grads_r)


def test_image_does_not_depend_on_tile_size():
  gaussians, cam = hard_scene(3, seed=5)
  outs = [render(gaussians, cam, settings=SMALL.replace(tile_size=t)) for t in (4, 16)]
  np.testing.assert_allclose(outs[0].rgb, outs[1].rgb, atol=2e-5)


def test_3dgs_rules_on_a_stack_of_opaque_gaussians():
  """Front-to-back order, alpha clamp at 0.99, stop below transmittance 1e-4."""
  cam = orbit_camera(16, 16, distance=4.0)
  center, fwd = np.asarray(cam.center), np.asarray(cam.rotation)[2]
  n = 4
  colors = np.eye(3)[[0, 1, 2, 0]]
  g = Gaussians(
      means=jnp.asarray(center + np.arange(1, n + 1)[:, None] * fwd, jnp.float32),
      scales=jnp.full((n, 3), 5.0, jnp.float32),
      quats=jnp.tile(jnp.array([1.0, 0, 0, 0]), (n, 1)),
      opacities=jnp.array([1.0, 0.5, 1.0, 1.0], jnp.float32),
      sh=jnp.asarray((colors - 0.5)[:, None, :] / 0.28209479177387814, jnp.float32))
  out = render(g, cam, settings=SMALL)
  px = out.rgb[8, 8]
  # Red: alpha clamped to 0.99, T = 0.01. Green: 0.5 * 0.01, T = 0.005. Blue would leave
  # T = 5e-5 < 1e-4: compositing stops there, so neither blue nor the last red count.
  np.testing.assert_allclose(px, [0.99, 0.005, 0.0], atol=1e-5)
  np.testing.assert_allclose(out.alpha[8, 8], 0.995, atol=1e-5)


# ------------------------------------------------------------------ gradients vs float64 FD


def test_gradients_match_float64_finite_differences():
  """Directional derivatives along random directions, one parameter group at a time.

  `offset` is the 2D-centre offset whose gradient densification thresholds.
  """
  fields = ("means", "scales", "quats", "opacities", "sh")
  with jax.enable_x64(True):
    g = random_gaussians(40, sh_degree=2, seed=11, scale_range=(0.05, 0.3),
                         opacity_range=(0.2, 0.8), dtype=jnp.float64)
    cam = orbit_camera(24, 20, distance=3.0)
    cam = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64), cam)
    weights = jnp.asarray(np.random.default_rng(0).normal(size=(20, 24, 5)))

    def loss(params):
      gaussians = replace(g, **{f: params[f] for f in fields})
      # The pose moves along the tangent of the rotation group plus a translation.
      omega, t = params["pose"][:3], params["pose"][3:]
      skew = jnp.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]],
                        [-omega[1], omega[0], 0]])
      delta = jnp.eye(4).at[:3, :3].set(jax.scipy.linalg.expm(skew)).at[:3, 3].set(t)
      camera = replace(cam, world_to_camera=delta @ cam.world_to_camera)
      out = render(gaussians, camera, background=jnp.array([0.3, 0.3, 0.3]), settings=SMALL,
                   screen_offset=params["offset"])
      return (jnp.sum(weights[..., :3] * out.rgb) + jnp.sum(weights[..., 3] * out.alpha)
              + 0.1 * jnp.sum(weights[..., 4] * out.depth))

    params = {f: getattr(g, f) for f in fields}
    params["pose"] = jnp.zeros(6)
    params["offset"] = jnp.zeros((g.num_gaussians, 2))
    f = jax.jit(loss)
    jvp = jax.jit(lambda p, d: jax.jvp(loss, (p,), (d,))[1])
    grad = jax.jit(jax.grad(loss))(params)
    rng = np.random.default_rng(1)
    eps = 1e-5
    for name in params:
      direction = jax.tree.map(jnp.zeros_like, params)
      direction[name] = jnp.asarray(rng.normal(size=params[name].shape))
      if name == "opacities":
        direction[name] *= 0.1
      forward = float(jvp(params, direction))
      plus = jax.tree.map(lambda a, d: a + eps * d, params, direction)
      minus = jax.tree.map(lambda a, d: a - eps * d, params, direction)
      fd = (float(f(plus)) - float(f(minus))) / (2 * eps)
      np.testing.assert_allclose(forward, fd, rtol=2e-4, atol=1e-8, err_msg=name)
      reverse = float(jnp.sum(grad[name] * direction[name]))
      np.testing.assert_allclose(reverse, forward, rtol=1e-6, atol=1e-10, err_msg=name)


def test_gradient_flows_through_look_at_to_eye():
  g = random_gaussians(30, sh_degree=1, seed=2, scale_range=(0.1, 0.3))

  def f(eye):
    cam = Camera.look_at(eye, jnp.zeros(3), jnp.array([0.0, 0.0, 1.0]), 0.9, 16, 16)
    return jnp.sum(render(g, cam, settings=SMALL).rgb ** 2)

  grad = jax.jit(jax.grad(f))(jnp.array([0.5, -3.0, 1.0]))
  assert np.all(np.isfinite(grad)) and float(jnp.linalg.norm(grad)) > 0


# ------------------------------------------------------------------ extremes


def _extreme_batch():
  """Same-shape scenes, each with one extreme property, stacked for one vmapped compile."""
  n = 8
  base = random_gaussians(n, sh_degree=1, seed=4, scale_range=(0.05, 0.2))
  cam = orbit_camera(16, 12, distance=3.0)
  center = jnp.asarray(cam.center, jnp.float32)
  on_camera_plane = center + 1.0 * cam.rotation[0]  # z = 0 in camera space
  cases = {
      "scale 1e-8": replace(base, scales=jnp.full((n, 3), 1e-8)),
      "scale 1e-4": replace(base, scales=jnp.full((n, 3), 1e-4)),
      "scale 1e4": replace(base, scales=jnp.full((n, 3), 1e4)),
      "mixed scales": replace(base, scales=base.scales.at[:, 0].set(1e-8).at[:, 1].set(1e4)),
      "opacity 0": replace(base, opacities=jnp.zeros(n)),
      "opacity 1": replace(base, opacities=jnp.ones(n)),
      "mean at camera": replace(base, means=base.means.at[0].set(center)),
      "mean on z=0": replace(base, means=base.means.at[0].set(on_camera_plane)),
      "zero quaternion": replace(base, quats=jnp.zeros((n, 4))),
      "all masked": replace(base, mask=jnp.zeros(n, bool)),
      "camera inside": replace(base, means=center + 0.5 * base.means),
  }
  cases = {k: replace(v, mask=v.mask if v.mask is not None else jnp.ones(n, bool))
           for k, v in cases.items()}
  batch = jax.tree.map(lambda *xs: jnp.stack(xs), *cases.values())
  return list(cases), batch, cam


def _grad_all(g, cam, settings):
  def loss(g, cam):
    out = render(g, cam, background=jnp.array([0.1, 0.2, 0.3]), settings=settings)
    return jnp.sum(out.rgb) + jnp.sum(out.alpha) + jnp.sum(out.depth)

  # allow_int: the boolean mask is a leaf too (its cotangent is float0).
  return jax.value_and_grad(loss, argnums=(0, 1), allow_int=True)(g, cam)


def _assert_finite(tree, label):
  for path, leaf in jax.tree_util.tree_leaves_with_path(tree):
    if leaf.dtype == jax.dtypes.float0:
      continue
    where = jax.tree_util.keystr(path)
    assert np.all(np.isfinite(np.asarray(leaf))), f"{label}: non-finite {where}"


def test_finite_outputs_and_gradients_at_extremes():
  names, batch, cam = _extreme_batch()
  settings = RenderSettings(max_intersections=1024, chunk_size=8, chunks_per_step=4)
  values, grads = jax.jit(jax.vmap(functools.partial(_grad_all, settings=settings),
                                   in_axes=(0, None)))(batch, cam)
  for i, name in enumerate(names):
    _assert_finite(values[i], name)
    _assert_finite(jax.tree.map(lambda x, i=i: x[i], grads[0]), name)
  _assert_finite(grads[1], "camera")  # summed over the batch by vmap's None axis


@pytest.mark.parametrize("num, width, height", [(0, 8, 8), (1, 8, 8), (5, 1, 1)])
def test_finite_for_tiny_inputs(num, width, height):
  g = random_gaussians(max(num, 1), sh_degree=0, seed=1, scale_range=(0.2, 0.5))
  g = jax.tree.map(lambda x: x[:num], g)
  cam = orbit_camera(width, height, distance=3.0)
  settings = RenderSettings(max_intersections=64, chunk_size=8, chunks_per_step=2)
  (value, grads) = _grad_all(g, cam, settings)
  _assert_finite((value, grads), f"N={num} {width}x{height}")
  out = render(g, cam, settings=settings)
  assert out.rgb.shape == (height, width, 3)
  if num == 0:
    np.testing.assert_array_equal(out.alpha, 0.0)


# ------------------------------------------------------------------ budgets


def test_overflow_is_reported_and_budget_growth_restores_the_image():
  from mfsample.renderer.budget import fit_budget, render_with_budget

  gaussians, cam = hard_scene(3)
  tight = RenderSettings(max_intersections=64, chunk_size=8, chunks_per_step=4)
  out = render(gaussians, cam, settings=tight)
  assert bool(out.stats.overflow)
  assert int(out.stats.num_padded) > 64
  grown = fit_budget(tight, out.stats)
  assert grown.max_intersections >= int(out.stats.num_padded)
  assert grown.max_intersections & (grown.max_intersections - 1) == 0  # a power of two
  full, used = render_with_budget(render, tight, gaussians, cam)
  assert not bool(full.stats.overflow)
  ref = render(gaussians, cam, settings=SMALL)
  np.testing.assert_allclose(full.rgb, ref.rgb, atol=1e-6)
  assert used.max_intersections <= 2 * max(64, int(full.stats.num_padded))


def test_stats_count_intersections():
  gaussians, cam = hard_scene(3)
  out = render(gaussians, cam, settings=SMALL)
  s = out.stats
  assert 0 < int(s.num_intersections) <= int(s.num_padded) <= SMALL.max_intersections
  assert int(s.num_padded) % SMALL.chunk_size == 0
  assert 0 < int(s.max_tile_load) <= int(s.num_intersections)
  assert not bool(s.overflow)


# ------------------------------------------------------------------ jit, vmap, retracing


def test_jit_and_no_jit_agree():
  gaussians = random_gaussians(12, sh_degree=1, seed=7, scale_range=(0.1, 0.4))
  cam = orbit_camera(20, 12, distance=3.0)
  settings = RenderSettings(max_intersections=256, chunk_size=16, chunks_per_step=8)
  jitted = render(gaussians, cam, settings=settings)
  assert not bool(jitted.stats.overflow)
  with jax.disable_jit():  # op by op: every stage run eagerly, loops in Python
    eager = render(gaussians, cam, settings=settings)
  np.testing.assert_allclose(eager.rgb, jitted.rgb, atol=1e-6)
  np.testing.assert_allclose(eager.depth, jitted.depth, atol=1e-5)


def test_second_call_with_same_shapes_does_not_retrace():
  @jax.jit
  @chex.assert_max_traces(n=1)
  def f(g, cam):
    return render(g, cam, settings=SMALL).rgb

  g1 = random_gaussians(20, sh_degree=1, seed=1)
  g2 = random_gaussians(20, sh_degree=1, seed=2)
  f(g1, orbit_camera(16, 16, azimuth=0.1))
  f(g2, orbit_camera(16, 16, azimuth=1.3))  # new values, same shapes: no retrace
  chex.clear_trace_counter()


def test_vmap_over_cameras_and_over_gaussians():
  g = random_gaussians(30, sh_degree=1, seed=3, scale_range=(0.05, 0.3))
  cams = [orbit_camera(16, 12, azimuth=a) for a in (0.0, 1.0, 2.0)]
  batch_cam = jax.tree.map(lambda *x: jnp.stack(x), *cams)
  fn = functools.partial(render, settings=SMALL)
  per_cam = jax.jit(jax.vmap(lambda c: fn(g, c).rgb))(batch_cam)
  for i, c in enumerate(cams):
    np.testing.assert_allclose(per_cam[i], fn(g, c).rgb, atol=1e-6)

  gs = [random_gaussians(30, sh_degree=1, seed=s) for s in (5, 6)]
  batch_g = jax.tree.map(lambda *x: jnp.stack(x), *gs)
  per_g = jax.jit(jax.vmap(lambda gg: fn(gg, cams[0]).rgb))(batch_g)
  for i, gg in enumerate(gs):
    np.testing.assert_allclose(per_g[i], fn(gg, cams[0]).rgb, atol=1e-6)


# ------------------------------------------------------------------ features, mask, errors


def test_features_are_composited_like_colours():
  gaussians, cam = hard_scene(3)
  feats = jnp.asarray(np.random.default_rng(0).uniform(size=(gaussians.num_gaussians, 5)),
                      jnp.float32)
  out = render(gaussians, cam, features=feats, settings=SMALL)
  ref = render_reference(gaussians, cam, features=feats, settings=SMALL)
  assert out.rgb.shape == (HEIGHT, WIDTH, 5)
  np.testing.assert_allclose(out.rgb, ref[0], atol=2e-5)
  grad = jax.grad(lambda f: jnp.sum(render(gaussians, cam, features=f, settings=SMALL).rgb))(
      feats)
  assert np.all(np.isfinite(grad)) and float(jnp.abs(grad).sum()) > 0


def test_screen_offset_moves_the_2d_centres_and_reports_footprints():
  """Training differentiates w.r.t. a zero `screen_offset` to get dL/d(2D centres)."""
  g, cam = hard_scene(0)
  base = render(g, cam, settings=SMALL)
  zero = render(g, cam, settings=SMALL, screen_offset=jnp.zeros((g.num_gaussians, 2)))
  np.testing.assert_array_equal(np.asarray(zero.rgb), np.asarray(base.rgb))
  assert base.radii.shape == base.visible.shape == (g.num_gaussians,)
  np.testing.assert_array_equal(np.asarray(base.radii)[~np.asarray(base.visible)], 0.0)
  assert 0 < int(base.visible.sum()) < g.num_gaussians  # the scene has culled Gaussians

  # The gradient itself is checked against finite differences in float64 above.
  loss = lambda off: jnp.sum(render(g, cam, settings=SMALL, screen_offset=off).rgb)
  grad = jax.grad(loss)(jnp.zeros((g.num_gaussians, 2)))
  assert np.all(np.isfinite(grad)) and np.any(np.asarray(grad) != 0)
  np.testing.assert_array_equal(np.asarray(grad)[~np.asarray(base.visible)], 0.0)


def test_masked_gaussians_change_nothing_and_get_no_gradient():
  g, cam = hard_scene(3)
  n, live = g.num_gaussians, g.num_gaussians - 5
  padding = jnp.arange(n) >= live
  masked = replace(g, mask=~padding)
  # The same scene without those Gaussians: zero opacity culls them exactly.
  removed = replace(g, mask=jnp.ones(n, bool), opacities=jnp.where(padding, 0.0, g.opacities))
  np.testing.assert_allclose(render(masked, cam, settings=SMALL).rgb,
                             render(removed, cam, settings=SMALL).rgb, atol=1e-6)
  grads = jax.grad(lambda gg: jnp.sum(render(gg, cam, settings=SMALL).rgb), allow_int=True)(
      masked)
  for leaf in jax.tree.leaves(replace(grads, mask=None)):
    np.testing.assert_array_equal(np.asarray(leaf)[live:], 0.0)
    assert np.any(np.asarray(leaf)[:live] != 0.0)


@pytest.mark.parametrize("change, message", [
    (lambda g: replace(g, sh=g.sh[:, :3]), "square"),
    (lambda g: replace(g, means=g.means[:, :2]), "means"),
    (lambda g: replace(g, opacities=g.opacities[:-1]), "opacities"),
    (lambda g: replace(g, scales=g.scales.astype(jnp.int32)), "floating"),
    (lambda g: replace(g, mask=jnp.ones(g.num_gaussians)), "boolean"),
])
def test_bad_gaussians_raise_clear_errors(change, message):
  g = random_gaussians(5, sh_degree=1)
  with pytest.raises(ValueError, match=message):
    jax.jit(lambda g: render(g, orbit_camera(8, 8), settings=SMALL).rgb)(change(g))


def test_bad_settings_and_cameras_raise():
  with pytest.raises(ValueError, match="multiple"):
    RenderSettings(max_intersections=100, chunk_size=32)
  with pytest.raises(ValueError, match="width"):
    orbit_camera(0, 8)
  g = random_gaussians(5)
  batch = jax.tree.map(lambda *x: jnp.stack(x), orbit_camera(8, 8), orbit_camera(8, 8))
  with pytest.raises(ValueError, match="vmap"):
    render(g, batch, settings=SMALL)
  with pytest.raises(ValueError, match="features"):
    render(g, orbit_camera(8, 8), features=jnp.ones((4, 2)), settings=SMALL)
