"""The Pallas compositing kernel against the jnp compositor, and its lowering for CUDA.

On a CPU the kernel runs in the Pallas interpreter: the same kernel code a GPU compiles, so
parity here is parity of the maths and of the indexing. Tolerances: images within 1e-5,
gradients within 1e-4 of the largest gradient of each parameter group. The scenes are tiny
(the interpreter is slow); every function is compiled once per settings.
"""

import functools
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import export  # a submodule that older JAX does not import with jax
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
  hard_scene,
  loss_weights,
  render_and_grads,
)

from mfsample import RenderSettings, orbit_camera, render
from mfsample._pytree import replace
from mfsample.renderer.composite_pallas import KernelParams, _forward, tile_ranges
from mfsample.testing import random_gaussians

IMAGE_ATOL = 1e-5
GRAD_RTOL = 1e-4


def pallas(settings):
  return settings.replace(compositor="pallas")


@pytest.mark.slow
def test_matches_jnp_on_the_hard_scene():
  """Behind the camera, across the near plane, off screen, needle-thin, huge, below alpha_min,
  nearly transparent; tiles spanning several chunks; non-square image with partial tiles."""
  gaussians, cam = hard_scene(3)
  weights = loss_weights()
  want, grads_want = render_and_grads(gaussians, cam, weights, settings=SMALL)
  got, grads_got = render_and_grads(gaussians, cam, weights, settings=pallas(SMALL))
  for g, w in zip(got, want, strict=True):
    np.testing.assert_allclose(g, w, atol=IMAGE_ATOL)
  assert_grads_close(grads_got, grads_want, rtol=GRAD_RTOL)


@pytest.mark.slow
def test_matches_jnp_at_extremes_vmapped_over_scenes():
  """Scales 1e-8 to 1e4, opacity 0 and 1, a mean at the camera and on its plane, a zero
  quaternion, everything masked (an empty scene), the camera inside the cloud: vmapped over
  the scenes as over M samples of one model."""
  names, batch, cam = extreme_batch()
  want, grads_want = batched_values_and_grads(batch, cam, settings=EXTREME_SETTINGS)
  got, grads_got = batched_values_and_grads(batch, cam, settings=pallas(EXTREME_SETTINGS))

  def scene(grads, i, name):  # scene i's gradients (Gaussians less the mask, camera)
    grads = (replace(grads[0], mask=None), grads[1])
    if name == "mixed scales":
      # A 1e-8 x 1e4 needle: its 2D covariance has a condition number ~1e12, so the
      # gradients w.r.t. its shape, its position and the camera are float32 rounding
      # amplified: the jnp compositor alone moves them by ~100% between tile sizes 8 and 16
      # (the same maths). Its opacity and colour gradients are compared.
      grads = (replace(grads[0], means=None, scales=None, quats=None), None)
    return jax.tree.map(lambda x: x[i], grads)

  for i, name in enumerate(names):
    assert_finite((got[i], scene(grads_got, i, "")), name)
    np.testing.assert_allclose(got[i], want[i], rtol=1e-6, atol=IMAGE_ATOL, err_msg=name)
    # The floor: leaves that are zero up to rounding (rotations of isotropic Gaussians).
    assert_grads_close(scene(grads_got, i, name), scene(grads_want, i, name), rtol=GRAD_RTOL,
                       floor=1e-9)


@functools.partial(jax.jit, static_argnames=("settings",))
def _render_and_grads_over_cameras(gaussians, cameras, weights, *, settings):
  """`render_and_grads` vmapped over cameras: outputs per camera, and the gradients of the
  sum of the cameras' losses (w.r.t. the Gaussians, and each camera)."""
  def outputs(g, cam):
    out = render(g, cam, background=BACKGROUND, settings=settings)
    return out.rgb, out.alpha, out.depth

  def loss(g, cams):
    rgb, alpha, depth = jax.vmap(outputs, in_axes=(None, 0))(g, cams)
    return (jnp.sum(weights[..., :3] * rgb) + jnp.sum(weights[..., 3] * alpha)
            + 0.1 * jnp.sum(weights[..., 4] * depth)), (rgb, alpha, depth)

  (_, images), grads = jax.value_and_grad(loss, argnums=(0, 1), has_aux=True)(
      gaussians, cameras)
  return images, grads


@pytest.mark.slow
def test_matches_jnp_under_vmap_over_cameras():
  """The kernel vmapped over two cameras against the jnp compositor camera by camera (vmap
  over samples of the Gaussians: the extremes above)."""
  gaussians, cam = hard_scene(3)
  other = orbit_camera(2.0, 0.5, width=WIDTH, height=HEIGHT, distance=2.8, fov_x=1.1)
  cams = jax.tree.map(lambda *x: jnp.stack(x), cam, other)
  weights = loss_weights()
  got, (grads_gaussians, grads_cams) = _render_and_grads_over_cameras(
      gaussians, cams, weights, settings=pallas(SMALL))
  grads_want = []
  for i, c in enumerate((cam, other)):
    want, grads = render_and_grads(gaussians, c, weights, settings=SMALL)
    assert float(jnp.max(want[1])) > 0.5  # the scene covers the image
    for g, w in zip(got, want, strict=True):
      np.testing.assert_allclose(g[i], w, atol=IMAGE_ATOL)
    assert_grads_close(jax.tree.map(lambda x, i=i: x[i], grads_cams), grads[1],
                       rtol=GRAD_RTOL)
    grads_want.append(grads[0])
  assert_grads_close(grads_gaussians, jax.tree.map(jnp.add, *grads_want), rtol=GRAD_RTOL)


def test_an_overflowing_budget_composites_the_same_truncated_lists():
  gaussians, cam = hard_scene(3)
  tight = SMALL.replace(max_intersections=64)
  want = render(gaussians, cam, settings=tight)
  got = render(gaussians, cam, settings=pallas(tight))
  assert bool(got.stats.overflow)
  np.testing.assert_allclose(got.rgb, want.rgb, atol=IMAGE_ATOL)
  np.testing.assert_allclose(got.alpha, want.alpha, atol=IMAGE_ATOL)


def test_kernel_lowers_for_cuda_on_a_cpu():
  """The forward and backward kernels, plain and batched, lower to Triton for CUDA.

  `jax.export` lowers for a platform without its device: on a CPU-only install this runs
  the Pallas-to-Triton lowering (the step a GPU run would otherwise fail first); Triton's
  compilation of that IR to PTX happens in XLA on the GPU itself.
  """
  settings = pallas(SMALL)
  g = random_gaussians(12, sh_degree=1, seed=1, scale_range=(0.1, 0.3))
  cams = jax.tree.map(lambda *x: jnp.stack(x), orbit_camera(0.1, 0.4, width=16, height=16,
                                                            distance=3.5),
                      orbit_camera(0.9, 0.4, width=16, height=16, distance=3.5))

  def loss(g, cam):
    return jnp.sum(render(g, cam, settings=settings).rgb)

  def batched_loss(g, cams):
    return jnp.sum(jax.vmap(loss, in_axes=(None, 0))(g, cams))

  triton = "__gpu$xla.gpu.triton"
  for fn, cam in ((loss, jax.tree.map(lambda x: x[0], cams)), (batched_loss, cams)):
    exported = export.export(
        jax.jit(jax.grad(fn, argnums=(0, 1))), platforms=("cuda",),
        disabled_checks=[export.DisabledSafetyCheck.custom_call(triton)])(g, cam)
    text = exported.mlir_module()
    assert exported.platforms == ("cuda",)
    assert text.count(f"@{triton}(") == 2, "one forward and one backward kernel"


def test_warps_setting_reaches_both_kernels():
  """`pallas_warps` is the Triton launch's warp count (0: one per 32 pixels of a tile)."""
  g = random_gaussians(12, sh_degree=1, seed=1, scale_range=(0.1, 0.3))
  cam = orbit_camera(0.1, 0.4, width=16, height=16, distance=3.5)
  triton = "__gpu$xla.gpu.triton"
  for warps, launched in ((0, 8), (2, 2)):
    settings = pallas(SMALL).replace(pallas_warps=warps)
    grad = jax.jit(jax.grad(lambda g, s=settings: jnp.sum(render(g, cam, settings=s).rgb)))
    text = export.export(grad, platforms=("cuda",), disabled_checks=[
        export.DisabledSafetyCheck.custom_call(triton)])(g).mlir_module()
    assert re.findall(r"num_warps = (\d+)", text) == [str(launched)] * 2


def test_backward_walk_starts_at_the_last_entry_a_pixel_blended():
  """The forward saves per pixel the position after the last entry it blended with
  alpha >= alpha_min: list entries behind it that reach no pixel centre (here 15 faint
  Gaussians centred on a pixel corner, whose footprints, 0.44 pixels across, hold no pixel
  centre) are not walked back, although no pixel of the tile ever saturates."""
  params = KernelParams(tile_size=16, tiles_x=1, num_tiles=1, chunk_size=8, width=16,
                        height=16, alpha_max=0.99, alpha_min=1 / 255, log_t_min=np.log(1e-4),
                        cut=-0.5 * 3.33**2)
  faint = [3.0, 3.0, 1.0, 0.0, 1.0, 1.1 / 255]  # mean x, y, conic a, b, c, opacity
  rows = np.array([[8.0, 8.0, 0.25, 0.0, 0.25, 0.5]] + [faint] * 15, np.float32)
  geometry = jnp.asarray(rows.reshape(2, 8, 6).transpose(0, 2, 1))  # [B, 6, C]
  features = jnp.ones((2, 1, 8), jnp.float32)
  first, count = jnp.array([0], jnp.int32), jnp.array([2], jnp.int32)
  _, coverage, _, last = _forward(params, first, count, geometry, features)
  assert 0.4 < float(jnp.max(coverage)) <= 0.5  # no pixel saturates
  # Pixels in the first Gaussian's footprint end after it, the others before any entry.
  np.testing.assert_array_equal(np.unique(last), [0, 1])


def test_tile_ranges_from_the_chunk_list():
  chunk_tile = jnp.array([0, 0, 2, 2, 2, 3, 5, 5, 5, 5], jnp.int32)  # 5 tiles; 5 = unused
  first, count = tile_ranges(chunk_tile, 5)
  np.testing.assert_array_equal(first, [0, 2, 2, 5, 6])
  np.testing.assert_array_equal(count, [2, 0, 3, 1, 0])


def test_settings_validate_the_compositor():
  with pytest.raises(ValueError, match="compositor"):
    RenderSettings(compositor="cuda")
  with pytest.raises(ValueError, match="powers of two"):
    RenderSettings(compositor="pallas", tile_size=12)
  with pytest.raises(ValueError, match="powers of two"):
    RenderSettings(compositor="pallas", chunk_size=24, max_intersections=24 * 16)
  with pytest.raises(ValueError, match="searchsorted_method"):
    RenderSettings(searchsorted_method="bisect")
  with pytest.raises(ValueError, match="pallas_warps"):
    RenderSettings(pallas_warps=3)
