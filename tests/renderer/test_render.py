"""The tiled renderer against the dense reference, gradients, extremes, jit/vmap behaviour."""

import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import float64
from render_testlib import (
  BACKGROUND,
  EXTREME_SETTINGS,
  HEIGHT,
  SMALL,
  WIDTH,
  assert_finite,
  assert_grads_close,
  batched_values_and_grads,
  extreme_batch,
  grad_all,
  hard_scene,
  loss_weights,
  render_and_grads,
)

from mfsample import Camera, Gaussians, RenderSettings, orbit_camera, render
from mfsample._pytree import replace
from mfsample.renderer.composite import composite
from mfsample.renderer.projection import footprint_sigma, project_gaussians, view_directions
from mfsample.renderer.reference import render_reference
from mfsample.renderer.sh import sh_to_color
from mfsample.renderer.tiles import intersect_tiles
from mfsample.testing import random_gaussians


@pytest.mark.parametrize("sh_degree, settings", [(3, SMALL), (0, RenderSettings())],
                         ids=["sh3-small-chunks", "sh0-default-settings"])
@pytest.mark.slow
def test_tiled_matches_dense_reference(sh_degree, settings):
  gaussians, cam = hard_scene(sh_degree)
  weights = loss_weights()
  (rgb, alpha, depth), grads = render_and_grads(gaussians, cam, weights, settings=settings)
  (rgb_r, alpha_r, depth_r), grads_r = render_and_grads(gaussians, cam, weights,
                                                         settings=settings, reference=True)
  assert rgb.shape == (HEIGHT, WIDTH, 3)
  np.testing.assert_allclose(rgb, rgb_r, atol=2e-5)
  np.testing.assert_allclose(alpha, alpha_r, atol=2e-5)
  np.testing.assert_allclose(depth, depth_r, atol=2e-4)
  assert float(alpha.max()) > 0.5, "the scene should cover part of the image"
  assert_grads_close(grads, grads_r)


@pytest.mark.slow
def test_image_does_not_depend_on_tile_size():
  gaussians, cam = hard_scene(3, seed=5)
  outs = [render(gaussians, cam, settings=SMALL.replace(tile_size=t)) for t in (8, 16)]
  np.testing.assert_allclose(outs[0].rgb, outs[1].rgb, atol=2e-5)


# ------------------------------------------------------------------ the rasterisation rule


def test_an_opaque_gaussian_contributes_to_its_alpha_cut_not_to_3_sigma():
  """Opacity 1: alpha = exp(-d^2 / 2) out to d = sqrt(2 ln 255) = 3.33 (so at 3.1-3.3 sigma,
  where the old 3-sigma rule cut it), and nothing beyond."""
  cam = orbit_camera(0.3, 0.4, width=32, height=32, distance=4.0)
  g = Gaussians(means=jnp.zeros((1, 3)), scales=jnp.full((1, 3), 0.3),
                quats=jnp.array([[1.0, 0, 0, 0]]), opacities=jnp.ones(1),
                sh=jnp.zeros((1, 1, 3)))
  proj = project_gaussians(g.means, g.scales, g.quats, g.opacities, None, cam,
                           RenderSettings())
  (u, v), (a, b, c) = np.asarray(proj.means2d[0]), np.asarray(proj.conics[0])
  dx, dy = np.meshgrid(np.arange(32) + 0.5 - u, np.arange(32) + 0.5 - v)
  d = np.sqrt(a * dx * dx + 2 * b * dx * dy + c * dy * dy)  # Mahalanobis distance [H, W]
  near_cut = (d > 3.1) & (d < 3.3)
  beyond = (d > 3.34) & (d < 4.0)
  assert near_cut.sum() >= 8 and beyond.sum() >= 8

  alpha = np.asarray(render(g, cam, settings=SMALL).alpha)
  np.testing.assert_allclose(alpha[near_cut], np.exp(-0.5 * d[near_cut] ** 2), rtol=1e-4)
  np.testing.assert_array_equal(alpha[beyond], 0.0)


@functools.partial(jax.jit, static_argnames=("settings", "three_sigma"))
def _render_with_square_footprints(g, cam, settings, three_sigma):
  """The renderer from its stages, every Gaussian listed in the tiles of the square around
  its footprint's bounding disc (the tile lists before bounding boxes) or, with
  `three_sigma`, around its 3-sigma disc whatever its opacity (the renderer before the alpha
  rule). Returns (rgb, stats)."""
  proj = project_gaussians(g.means, g.scales, g.quats, g.opacities, g.mask, cam, settings)
  radii = proj.radii
  if three_sigma:
    sigmas = footprint_sigma(g.opacities, settings)  # proj.radii = sigmas * sqrt(lambda_max)
    ok = proj.valid & (sigmas > 0)
    radii = jnp.where(ok, 3.0 * proj.radii / jnp.where(ok, sigmas, 1.0), 0.0)
  layout = intersect_tiles(proj._replace(extents=jnp.stack([radii, radii], -1)), cam.width,
                           cam.height, settings)
  colors = sh_to_color(g.sh, view_directions(g.means, cam))
  blend_in = jnp.concatenate([colors, proj.depths[:, None]], axis=-1)
  opacities = jnp.where(proj.valid, g.opacities, 0.0)
  blended, alpha = composite(layout, proj.means2d, proj.conics, opacities, blend_in,
                             cam.width, cam.height, settings)
  return blended[..., :3] + (1.0 - alpha)[..., None] * BACKGROUND, layout.stats


def test_radius_sigma_3_reproduces_the_3_sigma_renderer():
  """`radius_sigma=3.0` renders the images of the renderer before the alpha rule.

  Only the tile lists differ (a Gaussian of opacity < exp(4.5) / 255 = 0.35 is listed in
  the tiles of its smaller alpha footprint, where it contributes, not of its 3-sigma
  square), so the images agree to float rounding: sums are grouped into other chunks.
  """
  g, cam = hard_scene(3)
  settings = SMALL.replace(radius_sigma=3.0)
  new = render(g, cam, background=BACKGROUND, settings=settings)
  old_rgb, old_stats = _render_with_square_footprints(g, cam, settings, three_sigma=True)
  np.testing.assert_allclose(new.rgb, old_rgb, atol=1e-6)
  assert not bool(old_stats.overflow)
  assert int(new.stats.num_intersections) < int(old_stats.num_intersections)


def test_bounding_box_tile_lists_render_the_images_of_bounding_squares():
  """Listing a Gaussian in the tiles of its footprint's bounding box, not of the square
  around the footprint's bounding disc, drops only tiles where it contributes nothing:
  fewer intersections, the same image to float rounding."""
  g, cam = hard_scene(3)
  new = render(g, cam, background=BACKGROUND, settings=SMALL)
  old_rgb, old_stats = _render_with_square_footprints(g, cam, SMALL, three_sigma=False)
  np.testing.assert_allclose(new.rgb, old_rgb, atol=1e-6)
  assert not bool(old_stats.overflow)
  assert int(new.stats.num_intersections) < int(old_stats.num_intersections)


def test_running_every_loop_step_changes_nothing():
  """`skip_unused_steps=False` (no `lax.cond` in the jnp compositor's loop) computes the
  unused steps on empty chunks: the same images and gradients, plain and vmapped."""
  gaussians, cam = hard_scene(3)
  weights = loss_weights()
  every_step = SMALL.replace(skip_unused_steps=False)
  want, grads_want = render_and_grads(gaussians, cam, weights, settings=SMALL)
  got, grads_got = render_and_grads(gaussians, cam, weights, settings=every_step)
  assert int(render(gaussians, cam, settings=SMALL).stats.num_padded) < SMALL.max_intersections
  for g, w in zip(got, want, strict=True):  # float rounding: a few ulp of values near 1
    np.testing.assert_allclose(g, w, atol=1e-6)
  assert_grads_close(grads_got, grads_want, rtol=1e-5)
  cams = jax.tree.map(lambda *x: jnp.stack(x), cam, orbit_camera(2.0, 0.4, width=WIDTH,
                                                                 height=HEIGHT, distance=3.5))
  images = [jax.jit(jax.vmap(lambda c, s=s: render(gaussians, c, settings=s).rgb))(cams)
            for s in (SMALL, every_step)]
  np.testing.assert_allclose(images[1], images[0], atol=1e-7)


def test_3dgs_rules_on_a_stack_of_opaque_gaussians():
  """Front-to-back order, alpha clamp at 0.99, stop below transmittance 1e-4."""
  cam = orbit_camera(0.3, 0.4, width=16, height=16, distance=4.0)
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


@pytest.mark.slow
def test_gradients_match_float64_finite_differences():
  """Directional derivatives along random directions, one parameter group at a time.

  `offset` is the 2D-centre offset whose gradient densification thresholds. The alpha and
  radius cut-offs are discontinuities (a contribution of alpha_min appears or vanishes), so
  a finite difference that moves a pixel across one measures the jump, not the derivative:
  they are off here (alpha_min = 0; a 6-sigma cap, where alpha is below 1e-8).
  """
  fields = ("means", "scales", "quats", "opacities", "sh")
  smooth = SMALL.replace(alpha_min=0.0, radius_sigma=6.0)
  with float64():
    g = random_gaussians(40, sh_degree=2, seed=11, scale_range=(0.05, 0.3),
                         opacity_range=(0.2, 0.8), dtype=jnp.float64)
    cam = orbit_camera(0.3, 0.4, width=24, height=20, distance=3.0)
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
      out = render(gaussians, camera, background=jnp.array([0.3, 0.3, 0.3]), settings=smooth,
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


@pytest.mark.slow
def test_finite_outputs_and_gradients_at_extremes():
  names, batch, cam = extreme_batch()
  values, grads = batched_values_and_grads(batch, cam, settings=EXTREME_SETTINGS)
  for i, name in enumerate(names):
    assert_finite(values[i], name)
    assert_finite(jax.tree.map(lambda x, i=i: x[i], grads[0]), name)
  assert_finite(grads[1], "camera")  # summed over the batch by vmap's None axis


@pytest.mark.parametrize("num, width, height", [(0, 8, 8), (1, 8, 8), (5, 1, 1)])
@pytest.mark.slow
def test_finite_for_tiny_inputs(num, width, height):
  g = random_gaussians(max(num, 1), sh_degree=0, seed=1, scale_range=(0.2, 0.5))
  g = jax.tree.map(lambda x: x[:num], g)
  cam = orbit_camera(0.3, 0.4, width=width, height=height, distance=3.0)
  settings = RenderSettings(max_intersections=64, chunk_size=8, chunks_per_step=2)
  (value, grads) = grad_all(g, cam, settings)
  assert_finite((value, grads), f"N={num} {width}x{height}")
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


@pytest.mark.slow
def test_jit_and_no_jit_agree():
  gaussians = random_gaussians(12, sh_degree=1, seed=7, scale_range=(0.1, 0.4))
  cam = orbit_camera(0.3, 0.4, width=20, height=12, distance=3.0)
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
  f(g1, orbit_camera(0.1, 0.4, width=16, height=16, distance=3.5))
  f(g2, orbit_camera(1.3, 0.4, width=16, height=16,
                     distance=3.5))  # new values, same shapes: no retrace
  chex.clear_trace_counter()


@pytest.mark.slow
def test_vmap_over_cameras_and_over_gaussians():
  g = random_gaussians(30, sh_degree=1, seed=3, scale_range=(0.05, 0.3))
  cams = [orbit_camera(a, 0.4, width=16, height=12, distance=3.5) for a in (0.0, 1.0, 2.0)]
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_screen_offset_moves_the_2d_centres_and_reports_footprints():
  """Training differentiates w.r.t. a zero `screen_offset` to get dL/d(2D centres)."""
  g, cam = hard_scene(0)
  base = render(g, cam, settings=SMALL)
  zero = render(g, cam, settings=SMALL, screen_offset=jnp.zeros((g.num_gaussians, 2)))
  # Equal on a CPU; on a GPU XLA fuses the added zeros into a differently ordered program,
  # which moves a few pixels by one float32 ulp, so allow a few ulp.
  np.testing.assert_allclose(np.asarray(zero.rgb), np.asarray(base.rgb), rtol=5e-7, atol=1e-7)
  assert base.radii.shape == base.visible.shape == (g.num_gaussians,)
  np.testing.assert_array_equal(np.asarray(base.radii)[~np.asarray(base.visible)], 0.0)
  assert 0 < int(base.visible.sum()) < g.num_gaussians  # the scene has culled Gaussians

  # The gradient itself is checked against finite differences in float64 above.
  loss = lambda off: jnp.sum(render(g, cam, settings=SMALL, screen_offset=off).rgb)
  grad = jax.grad(loss)(jnp.zeros((g.num_gaussians, 2)))
  assert np.all(np.isfinite(grad)) and np.any(np.asarray(grad) != 0)
  np.testing.assert_array_equal(np.asarray(grad)[~np.asarray(base.visible)], 0.0)


@functools.partial(jax.jit, static_argnames=("settings",))
def _images_and_grads(batch, cam, settings):
  """(rgb, visible) of each scene of a same-shape batch, and the gradient of its sum."""
  def one(g):
    out = render(g, cam, background=BACKGROUND, settings=settings)
    return jnp.sum(out.rgb) + jnp.sum(out.depth), (out.rgb, out.visible)

  grad_fn = jax.value_and_grad(one, has_aux=True, allow_int=True)
  (_, images), grads = jax.vmap(grad_fn)(batch)
  return images, grads


@pytest.mark.parametrize("compositor", ["jnp", pytest.param("pallas", marks=pytest.mark.slow)])
def test_non_finite_gaussians_are_culled_and_poison_nothing(compositor):
  """A NaN in a masked-out Gaussian at slot 0 (the slot padding entries point at) and a NaN
  colour in one visible Gaussian: every pixel stays finite and equals the render without
  those Gaussians, and their gradients are 0, not NaN."""
  n, k = 16, 5
  g = random_gaussians(n, sh_degree=1, seed=8, scale_range=(0.1, 0.4))
  g = replace(g, mask=jnp.ones(n, bool).at[0].set(False))
  cam = orbit_camera(0.3, 0.4, width=16, height=16, distance=3.0)
  poisoned = replace(g, means=g.means.at[0].set(jnp.nan), sh=g.sh.at[0].set(jnp.nan)
                     .at[k, 0, 1].set(jnp.nan))
  without = replace(g, mask=g.mask.at[k].set(False))
  batch = jax.tree.map(lambda *x: jnp.stack(x), g, poisoned, without)
  (rgb, visible), grads = _images_and_grads(batch, cam, SMALL.replace(compositor=compositor))
  rgb, visible = np.asarray(rgb), np.asarray(visible)
  assert visible[0, k] and not visible[1, k] and not visible[1, 0]
  assert np.all(np.isfinite(rgb[1]))
  np.testing.assert_array_equal(rgb[1], rgb[2])
  assert np.any(rgb[0] != rgb[1])  # Gaussian k did show when it was finite
  for leaf in jax.tree.leaves(replace(grads, mask=None)):
    leaf = np.asarray(leaf)[1]
    assert np.all(np.isfinite(leaf))
    np.testing.assert_array_equal(leaf[[0, k]], 0.0)
    assert np.any(leaf != 0.0)


@pytest.mark.slow
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
    jax.jit(lambda g: render(g, orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5),
                             settings=SMALL).rgb)(change(g))


def test_bad_settings_and_cameras_raise():
  with pytest.raises(ValueError, match="multiple"):
    RenderSettings(max_intersections=100, chunk_size=32)
  with pytest.raises(ValueError, match="width"):
    orbit_camera(0.3, 0.4, width=0, height=8, distance=3.5)
  g = random_gaussians(5)
  one = orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5)
  batch = jax.tree.map(lambda *x: jnp.stack(x), one, one)
  with pytest.raises(ValueError, match="vmap"):
    render(g, batch, settings=SMALL)
  with pytest.raises(ValueError, match="features"):
    render(g, orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5), features=jnp.ones((4, 2)),
           settings=SMALL)


def test_the_dense_reference_renders_what_the_tiled_renderer_does_on_a_tiny_scene():
  """`render_reference` (every Gaussian at every pixel, no tiles, no budget) against the
  tiled renderer, forward only, on a few Gaussians at 8 x 8 (the fast tier's check; the
  hard scenes and gradients: test_tiled_matches_dense_reference)."""
  gaussians = random_gaussians(12, sh_degree=0, seed=4)
  cam = orbit_camera(0.3, 0.4, width=8, height=8, distance=4.0)
  want = render(gaussians, cam, background=BACKGROUND, settings=SMALL)
  rgb, alpha, depth = render_reference(gaussians, cam, background=BACKGROUND, settings=SMALL)
  np.testing.assert_allclose(rgb, want.rgb, atol=1e-5)
  np.testing.assert_allclose(alpha, want.alpha, atol=1e-5)
  assert float(jnp.max(alpha)) > 0.05  # the Gaussians are in view
