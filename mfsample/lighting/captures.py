"""What the light planner photographs: basis images of fixed cameras, captures under any light.

The cameras are fixed; the lights change. The oracle renders, once per camera, the image
under each SH basis function Y_b alone (I_b, signed linear radiance); the capture under any
light xi is then sum_b xi_b I_b (`capture`), exact by the linearity of light transport, so a
new light costs no rendering. The data kinds that offer lights (`mfsample.data.DATA_KINDS`)
make their `LightData` here:

* "scene": a built-in Mitsuba scene (`scene_light_data`: `mfsample.scenes.capture_sh_basis`,
  cached on disk per camera); training cameras `scene.candidate_cameras`, test cameras
  `scene.test_cameras`.
* "synthetic": random ground-truth Gaussians (an opaque shell) with a diffuse (Lambertian)
  transfer about each Gaussian's outward normal, rendered by `mfsample.render`
  (`synthetic_light_data`: tests and the notebook, no files, no Mitsuba). Being diffuse, it
  has m = 1 exactly; shadowing is not modelled.

The background is black (radiance 0), as the oracle's SH captures are.
"""

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample.camera import Camera
from mfsample.lighting import lights as lights_lib
from mfsample.renderer import RenderSettings, render
from mfsample.renderer import sh as sh_lib
from mfsample.renderer.budget import render_with_budget


class LightData(NamedTuple):
  """Cameras and their basis images.

  Attributes:
    name: scene name.
    train_cameras: `Camera` [V], where training captures are taken.
    test_cameras: `Camera` [T], held out.
    train_basis: [V, n, H, W, 3] float32 images under each basis light.
    test_basis: [T, n, H, W, 3] float32.
    bounds: (low [3], high [3]) box of the scene (the random initial point cloud).
  """

  name: str
  train_cameras: Camera
  test_cameras: Camera
  train_basis: np.ndarray
  test_basis: np.ndarray
  bounds: tuple

  @property
  def light_coeffs(self):
    return self.train_basis.shape[1]


def capture(basis, xi):
  """Images [V, H, W, 3] under the white light xi from basis images [V, n, H, W, 3].

  Linear radiance, signed where the light is; `mfsample.scenes.relight` per camera.
  """
  basis = _check_basis(basis)
  xi = lights_lib.check_light(xi, basis.shape[1])
  return np.einsum("vbhwc,b->vhwc", basis, xi.astype(basis.dtype)).astype(np.float32)


def capture_many(basis, lights):
  """Images [K, V, H, W, 3] under each of `lights` [K, n]."""
  basis = _check_basis(basis)
  lights = lights_lib.check_lights(lights, basis.shape[1])
  return np.einsum("vbhwc,kb->kvhwc", basis, lights.astype(basis.dtype)).astype(np.float32)


def _check_basis(basis):
  basis = np.asarray(basis)
  if basis.ndim != 5 or basis.shape[-1] != 3:
    raise ValueError(f"basis must have shape [V, n, H, W, 3] (images under each basis light), "
                     f"got {list(basis.shape)}")
  if not np.issubdtype(basis.dtype, np.floating):
    raise ValueError(f"basis must hold floats (linear radiance), got dtype {basis.dtype}")
  return basis


def scene_light_data(spec, n) -> LightData:
  """The `LightData` of a built-in Mitsuba scene (`DataSpec` of kind "scene"): SH basis
  captures of degree sqrt(n) - 1 at its candidate and test cameras (cached per camera)."""
  import tqdm

  from mfsample import scenes
  from mfsample.data import resolve_path

  scene = scenes.get_scene(spec.scene)
  w, h = spec.width, spec.height
  train = scene.candidate_cameras(w, h, num=spec.num_train, seed=spec.camera_seed)
  test = scene.test_cameras(w, h, num=spec.num_test, seed=spec.camera_seed + 1)
  cache = str(resolve_path(spec.cache_dir)) if spec.cache_dir else None
  degree = lights_lib.degree_of(n)
  cams = [(train, i) for i in range(len(train))] + [(test, i) for i in range(len(test))]
  bar = tqdm.tqdm(cams, desc=f"SH basis captures of {scene.name}", unit="view",
                  disable=not spec.progress)
  images = [scenes.capture_sh_basis(scene, c[i], degree=degree, spp=spec.spp,
                                    cache_dir=cache) for c, i in bar]
  c, r = np.asarray(scene.center, np.float64), float(scene.radius)
  return LightData(scene.name, train, test, np.stack(images[:len(train)]),
                   np.stack(images[len(train):]), (c - r, c + r))


# Lambertian transfer per SH band (Ramamoorthi & Hanrahan 2001): irradiance
# E(n) = sum_b A_l(b) xi_b Y_b(n), radiance = albedo E / pi.
_LAMBERT_BANDS = (math.pi, 2.0 * math.pi / 3.0, math.pi / 4.0, 0.0)


def diffuse_radiance(truth, seed, n):
  """[N, n, 3] per-Gaussian radiance under each basis light of the ground truth `truth`
  (`Gaussians`) made diffuse: albedo uniform in [0.1, 0.9] (seeded by `seed`), Lambertian
  transfer about each Gaussian's outward normal (from the origin)."""
  rng = np.random.default_rng([int(seed), 39])
  albedo = rng.uniform(0.1, 0.9, (truth.num_gaussians, 3))
  normals = np.asarray(truth.means, np.float64)
  normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
  degree = lights_lib.degree_of(n)
  bands = np.floor(np.sqrt(np.arange(n)) + 1e-6).astype(int)
  y = np.asarray(sh_lib.sh_basis(jnp.asarray(normals, jnp.float32), degree), np.float64)
  per_light = y * np.asarray(_LAMBERT_BANDS)[bands] / math.pi  # [N, n]
  return jnp.asarray(per_light[:, :, None] * albedo[:, None, :], jnp.float32)


def synthetic_light_data(truth, seed, train_cameras, test_cameras, n, *, bounds) -> LightData:
  """The `LightData` of synthetic ground-truth Gaussians `truth` made diffuse
  (`diffuse_radiance`), rendered by mfsample at the training and test cameras."""
  per_light = diffuse_radiance(truth, seed, n)
  settings = RenderSettings(max_intersections=1 << 12)

  def basis_images(cameras, settings):
    out = []  # diffuse: the radiance features do not depend on the view direction
    for i in range(len(cameras)):
      cam = cameras[i]
      res, settings = render_with_budget(
          render, settings, truth, cam, features=per_light.reshape(per_light.shape[0], n * 3))
      out.append(np.asarray(res.rgb).reshape(cam.height, cam.width, n, 3))
    return np.moveaxis(np.stack(out), 3, 1), settings

  train, settings = basis_images(train_cameras, settings)
  test, _ = basis_images(test_cameras, settings)
  return LightData("synthetic", train_cameras, test_cameras, train, test, bounds)


def to_device_cameras(cameras):
  """A `Camera` batch with jnp leaves (indexed inside jit)."""
  return jax.tree.map(jnp.asarray, cameras)
