"""Synthetic scenes for tests, benchmarks and notebooks."""

import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.gaussians import Gaussians


def random_gaussians(num, *, sh_degree=3, seed=0, extent=1.0, scale_range=(0.01, 0.1),
                     opacity_range=(0.1, 1.0), dtype=jnp.float32):
  """`num` random Gaussians with centres uniform in [-extent, extent]^3.

  Scales are log-uniform in `scale_range` (times `extent`), rotations uniform, SH
  coefficients small so colours stay in a visible range.
  """
  rng = np.random.default_rng(seed)
  lo, hi = np.log(scale_range[0] * extent), np.log(scale_range[1] * extent)
  k = (sh_degree + 1) ** 2
  sh = rng.normal(0.0, 0.3, (num, k, 3))
  sh[:, 1:] *= 0.5
  return Gaussians(
      means=jnp.asarray(rng.uniform(-extent, extent, (num, 3)), dtype),
      scales=jnp.asarray(np.exp(rng.uniform(lo, hi, (num, 3))), dtype),
      quats=jnp.asarray(rng.normal(size=(num, 4)), dtype),
      opacities=jnp.asarray(rng.uniform(*opacity_range, (num,)), dtype),
      sh=jnp.asarray(sh, dtype),
  )


def orbit_camera(width, height, *, azimuth=0.3, elevation=0.4, distance=3.5, fov_x=0.9,
                 target=(0.0, 0.0, 0.0)):
  """A camera on a sphere around `target` (up = +z), looking at it."""
  target = np.asarray(target, np.float64)
  eye = target + distance * np.array([np.cos(elevation) * np.cos(azimuth),
                                      np.cos(elevation) * np.sin(azimuth),
                                      np.sin(elevation)])
  return Camera.look_at(jnp.asarray(eye, jnp.float32), jnp.asarray(target, jnp.float32),
                        jnp.array([0.0, 0.0, 1.0]), fov_x, width, height)
