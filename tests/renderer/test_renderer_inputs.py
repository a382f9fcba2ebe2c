"""Hostile inputs to the renderer.

For each entry point, a table of bad inputs and what they give: each row is a bad input and
its expected outcome, a clear error whose message names the field or the file, or a defined
behaviour (docs/reliability.md lists the same tables).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hostile_testlib import BAD_POSES, NAN, SMALL, W2C

from mfsample import orbit_camera
from mfsample._pytree import replace
from mfsample.camera import Camera
from mfsample.renderer import RenderSettings, render
from mfsample.renderer.budget import render_with_budget
from mfsample.testing import random_gaussians

# ====================================================================== render's inputs


def test_render_gives_nan_images_for_invalid_cameras():
  """Invalid cameras cannot raise under jit: their images are NaN (rgb, alpha, depth), so any
  finiteness check catches them, and the valid cameras of the batch are unaffected."""
  g = random_gaussians(24, sh_degree=0, seed=3, extent=0.5, scale_range=(0.1, 0.3),
                       opacity_range=(0.5, 0.9))
  names = ["valid", *BAD_POSES]
  rows = [(W2C, 8.0, 8.0, 8.0, 8.0)] + [BAD_POSES[n][:5] for n in BAD_POSES]
  cams = Camera(*(jnp.asarray(np.stack([np.asarray(r[i], np.float64) for r in rows]),
                              jnp.float32) for i in range(5)), 16, 16)
  out = jax.jit(jax.vmap(lambda c: render(g, c, settings=SMALL)))(cams)
  for i, name in enumerate(names):
    for what in ("rgb", "alpha", "depth"):
      image = np.asarray(getattr(out, what)[i])
      if name == "valid":
        assert np.all(np.isfinite(image)), what
      else:
        assert np.all(np.isnan(image)), (name, what)
  assert float(np.max(out.alpha[0])) > 0.1  # the valid camera sees the Gaussians


@pytest.mark.parametrize("call, error, message", [
    (lambda g, c: render(g, Camera.create(np.stack([W2C] * 2), 8, 8, 8, 8, 16, 16)),
     ValueError, "one camera"),
    (lambda g, c: render(g, W2C), TypeError, "mfsample.Camera"),
    (lambda g, c: render(g, c, features=jnp.ones((3, 2))), ValueError, "features must have"),
    (lambda g, c: render(replace(g, means=g.means[:, :2]), c), ValueError, "Gaussians.means"),
    (lambda g, c: render(replace(g, sh=jnp.zeros((4, 5, 3))), c), ValueError, "SH axis"),
    (lambda g, c: render(replace(g, mask=jnp.ones(4, jnp.int32)), c), ValueError,
     "mask must be boolean"),
    (lambda g, c: render(replace(g, opacities=jnp.ones(4, jnp.int32)), c), ValueError,
     "opacities must be floating"),
    (lambda g, c: render(g, c, background=jnp.ones(4)), ValueError,
     r"background must have shape \[3\] .*RGB colour\), got \[4\]"),
    (lambda g, c: render(g, c, features=jnp.ones((4, 2)), background=jnp.ones(3)), ValueError,
     r"background must have shape \[2\] \(one value per channel of features\)"),
    (lambda g, c: render(g, c, screen_offset=jnp.zeros((4, 3))), ValueError,
     r"screen_offset must have shape \[N=4, 2\], got \[4, 3\]"),
    (lambda g, c: RenderSettings(radius_sigma=NAN), ValueError,
     "RenderSettings.radius_sigma must be a finite number > 0.0, got nan"),
    (lambda g, c: RenderSettings(tile_size=2.5), ValueError,
     "RenderSettings.tile_size must be an integer >= 1, got 2.5"),
    (lambda g, c: render_with_budget(render, SMALL, g, c, max_budget=0), ValueError,
     "max_budget must be an integer >= 1, got 0"),
])
def test_render_input_table(call, error, message):
  g = random_gaussians(4, sh_degree=0, seed=0)
  with pytest.raises(error, match=message):
    call(g, orbit_camera(0.3, 0.4, width=16, height=16, distance=3.5))
