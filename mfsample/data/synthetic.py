"""Synthetic scenes: random ground-truth Gaussians and cameras around them, no files needed.

Two scenes serve tests, the tiny variants of every experiment and the notebooks:

* `random_gaussians` / `synthetic_gaussians`: Gaussians with centres uniform in a cube
  (training's "synthetic" data kind renders them from `orbit_cameras`);
* `synthetic_scene`: an opaque "shell" on a sphere (every view sees one side of a closed
  surface, none sees through it) or a see-through "cloud": the planning pool, the AUSE arc
  and the light-planning captures of kind "synthetic".

`render_views` renders any Gaussians into ground-truth `Views` (colour, alpha, depth).
"""

import dataclasses

import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.data.views import Views
from mfsample.gaussians import Gaussians
from mfsample.renderer import render
from mfsample.renderer.budget import render_with_budget
from mfsample.renderer.settings import RenderSettings
from mfsample.renderer.sh import rgb_to_sh_dc


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


def synthetic_gaussians(num, seed, sh_degree=0, radius=0.6):
  """`num` random, fairly opaque Gaussians in the cube [-radius, radius]^3."""
  return random_gaussians(num, sh_degree=sh_degree, seed=seed, extent=radius,
                          scale_range=(0.04, 0.12), opacity_range=(0.6, 0.95))


def synthetic_scene(num, seed, radius=0.6, sh_degree=0, shape="shell"):
  """Random ground-truth Gaussians: an opaque "shell" (on the sphere of `radius`: every view
  sees one side of a closed surface and none sees through it) or a "cloud" (in the cube
  [-radius, radius]^3)."""
  rng = np.random.default_rng(seed)
  k = (sh_degree + 1) ** 2
  sh = np.zeros((num, k, 3), np.float32)
  sh[:, 0] = np.asarray(rgb_to_sh_dc(rng.uniform(0.05, 0.95, (num, 3))))
  if shape == "shell":
    means = rng.normal(size=(num, 3))
    means *= radius / np.linalg.norm(means, axis=1, keepdims=True)
    # Footprints that overlap into a closed surface: about 2x the mean spacing.
    size = 2.0 * radius * np.sqrt(4.0 * np.pi / num)
    scales = np.exp(rng.uniform(np.log(0.6 * size), np.log(size), (num, 3)))
    opacities = rng.uniform(0.85, 0.99, num)
  elif shape == "cloud":
    means = rng.uniform(-radius, radius, (num, 3))
    scales = np.exp(rng.uniform(np.log(0.03), np.log(0.12), (num, 3)))
    opacities = rng.uniform(0.5, 0.95, num)
  else:
    raise ValueError(f"synthetic shape must be 'shell' or 'cloud', got {shape!r}")
  return Gaussians(
      means=jnp.asarray(means, jnp.float32), scales=jnp.asarray(scales, jnp.float32),
      quats=jnp.asarray(rng.normal(size=(num, 4)), jnp.float32),
      opacities=jnp.asarray(opacities, jnp.float32), sh=jnp.asarray(sh))


def orbit_cameras(num, width, height, distance=3.0, fov_x=0.8, seed=0, offset=0.0):
  """`num` cameras on a sphere looking at the origin (a Fibonacci spiral, +z up)."""
  del seed  # the spiral is deterministic; kept for a uniform signature
  i = np.arange(num) + 0.5 + offset
  polar = np.arccos(np.clip(1.0 - 2.0 * i / (num + 2 * offset), -0.95, 0.95))
  azimuth = np.pi * (1.0 + 5.0**0.5) * i
  eye = distance * np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                             np.cos(polar)], axis=-1)
  return Camera.look_at(jnp.asarray(eye, jnp.float32), jnp.zeros(3), jnp.array([0.0, 0, 1]),
                        fov_x, width, height)


def render_views(gaussians, cameras, background, settings=None, names=None):
  """Renders `gaussians` into every camera: ground-truth `Views` (colour, alpha, depth)."""
  settings = settings or RenderSettings()
  images, alphas, depths = [], [], []
  bg = jnp.asarray(background, jnp.float32)
  for i in range(len(cameras)):
    out, settings = render_with_budget(render, settings, gaussians, cameras[i],
                                       background=bg)
    images.append(out.rgb)
    alphas.append(out.alpha)
    depths.append(out.expected_depth())
  names = tuple(names) if names else tuple(f"view_{i:03d}" for i in range(len(cameras)))
  return Views(jnp.clip(jnp.stack(images), 0.0, 1.0), cameras, jnp.stack(alphas),
               jnp.stack(depths), names)


@dataclasses.dataclass(frozen=True, eq=False)
class Oracle:
  """The ground truth of any camera: `oracle(camera)` -> [H, W, 3] image in [0, 1] (numpy).

  Holds no state: every call starts from `settings`' budget and grows it where the render
  needs more (`render_with_budget`), so a call never depends on the calls before it.
  """

  truth: Gaussians
  background: tuple
  settings: RenderSettings = RenderSettings(max_intersections=1 << 12)

  def __call__(self, camera):
    out, _ = render_with_budget(render, self.settings, self.truth, camera,
                                background=jnp.asarray(self.background, jnp.float32))
    return np.asarray(jnp.clip(out.rgb, 0.0, 1.0))
