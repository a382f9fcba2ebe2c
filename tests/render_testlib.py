"""Scenes and checks shared by the renderer tests (`test_render.py`, `test_composite_pallas.py`).

Functions are jitted here, at module level, with their settings static: tests that use equal
settings share one compilation.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import Gaussians, RenderSettings, orbit_camera, render
from mfsample._pytree import replace
from mfsample.renderer.reference import render_reference
from mfsample.testing import random_gaussians

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
  return orbit_camera(0.7, 0.3, width=WIDTH, height=HEIGHT, distance=2.6, fov_x=1.1)


BACKGROUND = jnp.array([0.2, 0.5, 0.9])


@functools.partial(jax.jit, static_argnames=("settings", "reference"))
def render_and_grads(gaussians, camera, weights, *, settings, reference=False):
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


def loss_weights(seed=3):
  return jnp.asarray(np.random.default_rng(seed).normal(size=(HEIGHT, WIDTH, 5)), jnp.float32)


def assert_grads_close(got, want, rtol=2e-3, floor=0.0):
  """Every leaf within rtol of the largest magnitude of that leaf in `want`, plus `floor`
  (for leaves that are zero up to rounding, e.g. the rotation of an isotropic Gaussian)."""
  for path, g, w in zip(jax.tree_util.tree_leaves_with_path(got),
                        jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
    scale = float(np.max(np.abs(w))) + 1e-12
    np.testing.assert_allclose(np.asarray(g), np.asarray(w), rtol=rtol,
                               atol=rtol * scale + floor,
                               err_msg=jax.tree_util.keystr(path[0]))


def extreme_batch():
  """Same-shape scenes, each with one extreme property, stacked for one vmapped compile."""
  n = 8
  base = random_gaussians(n, sh_degree=1, seed=4, scale_range=(0.05, 0.2))
  cam = orbit_camera(0.3, 0.4, width=16, height=12, distance=3.0)
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


EXTREME_SETTINGS = RenderSettings(max_intersections=1024, chunk_size=8, chunks_per_step=4)


def grad_all(g, cam, settings):
  def loss(g, cam):
    out = render(g, cam, background=jnp.array([0.1, 0.2, 0.3]), settings=settings)
    return jnp.sum(out.rgb) + jnp.sum(out.alpha) + jnp.sum(out.depth)

  # allow_int: the boolean mask is a leaf too (its cotangent is float0).
  return jax.value_and_grad(loss, argnums=(0, 1), allow_int=True)(g, cam)


def assert_finite(tree, label):
  for path, leaf in jax.tree_util.tree_leaves_with_path(tree):
    if leaf.dtype == jax.dtypes.float0:
      continue
    where = jax.tree_util.keystr(path)
    assert np.all(np.isfinite(np.asarray(leaf))), f"{label}: non-finite {where}"




@functools.partial(jax.jit, static_argnames=("settings",))
def batched_values_and_grads(batch, cam, *, settings):
  """`grad_all` vmapped over a batch of same-shape scenes (one camera)."""
  return jax.vmap(functools.partial(grad_all, settings=settings), in_axes=(0, None))(batch, cam)
