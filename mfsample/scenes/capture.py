"""Ground-truth captures: physically based renders of a `Scene` at any camera and any SH light.

A capture is what the planners "photograph" after choosing a pose or a light. It uses the
same camera conventions as `mfsample.Camera` and `mfsample.render` (OpenCV axes, pixel
(i, j) centred at (j + 1/2, i + 1/2)). Radiance is linear (no tone mapping), so that light
transport stays linear in the emitted light: the image under an SH light xi is
sum_j xi_j I_j exactly (`capture_sh_basis`, `relight`).

Every capture goes through the on-disk cache (`mfsample.scenes.cache`): capturing the same
scene, camera, resolution, spp and variant again only reads a file.
"""

import dataclasses
import math

import numpy as np
import tqdm

from mfsample.camera import Camera
from mfsample.data.views import Views
from mfsample.renderer import sh as sh_lib
from mfsample.scenes import cache as cache_lib
from mfsample.scenes import mitsuba_bridge as bridge

# Samples per pixel of ordinary captures (a perfect square: stratified sampling): about
# 1 s per 100 x 100 view with the scalar variant, 0.1 s with the LLVM one
# (benchmarks/capture.py).
DEFAULT_SPP = 36
# SH basis captures render 2 (degree + 1)^2 - 1 = 31 lights per camera at degree 3.
DEFAULT_SH_SPP = 16
# Lat-long resolution of the SH environment maps (bilinear in between; SH up to degree 3
# varies slowly, so 64 x 128 texels keep the interpolation error far below the MC noise).
ENV_HEIGHT, ENV_WIDTH = 64, 128


def capture(scene, camera, *, spp=DEFAULT_SPP, cache_dir=None, background=(1.0, 1.0, 1.0),
            variant=None, cache=True):
  """Captures one view under the scene's fixed lighting.

  Args:
    scene: a `Scene` (e.g. `get_scene()`).
    camera: one unbatched `Camera` (square pixels: fx == fy).
    spp: samples per pixel, a perfect square (stratified sampler).
    cache_dir: cache folder (default: $MFSAMPLE_CACHE or ~/.cache/mfsample/captures).
    background: [3] colour composited behind the scene.
    variant: Mitsuba variant ("scalar_rgb", "llvm_ad_rgb" or "auto"; default:
      $MFSAMPLE_MITSUBA_VARIANT or "scalar_rgb").
    cache: False to neither read nor write the cache.

  Returns:
    (rgb [H, W, 3] float32 in [0, 1]: linear radiance composited on `background` and
    clipped; alpha [H, W] float32: fraction of each pixel covered by the scene;
    depth [H, W] float32: mean camera z-depth of what the pixel sees (world units), 0
    where alpha == 0).
  """
  if not isinstance(camera, Camera) or camera.batch_shape:
    raise ValueError("capture takes one unbatched Camera; use capture_views for a batch")
  (entry, _), = _capture_entries(scene, [camera], spp=spp, cache_dir=cache_dir,
                                 variant=variant, cache=cache, progress=False)
  return _composite(entry, background) + (entry["depth"],)


@dataclasses.dataclass(frozen=True, eq=False)
class Oracle:
  """A scene's ground truth at any camera: `oracle(camera)` -> [H, W, 3] image (`capture`'s
  colour, cached on disk), for the strategies that propose new poses."""

  scene: object
  spp: int = DEFAULT_SPP
  cache_dir: str | None = None
  background: tuple = (1.0, 1.0, 1.0)

  def __call__(self, camera):
    return capture(self.scene, camera, spp=self.spp, cache_dir=self.cache_dir,
                   background=self.background)[0]


def capture_views(scene, cameras, *, spp=DEFAULT_SPP, cache_dir=None, progress=True,
                  background=(1.0, 1.0, 1.0), variant=None, cache=True) -> Views:
  """Captures a batch of cameras (see `capture`), with a progress bar.

  Args:
    scene: a `Scene`.
    cameras: a `Camera` batched over V (e.g. `scene.candidate_cameras(100, 100)`).
    spp, cache_dir, background, variant, cache: as in `capture`.
    progress: show a tqdm progress bar.

  Returns:
    `Views` with images, alphas and metric depths [V, H, W], the cameras, and names
    "{scene.name}-{cache key prefix}".
  """
  if not isinstance(cameras, Camera) or len(cameras.batch_shape) != 1:
    raise ValueError("capture_views takes a Camera batched over one axis")
  cams = [cameras[i] for i in range(len(cameras))]
  entries = _capture_entries(scene, cams, spp=spp, cache_dir=cache_dir, variant=variant,
                             cache=cache, progress=progress)
  rgbs, alphas = zip(*(_composite(e, background) for e, _ in entries), strict=True)
  return Views(images=np.stack(rgbs), cameras=cameras, alphas=np.stack(alphas),
               depths=np.stack([e["depth"] for e, _ in entries]),
               names=tuple(f"{scene.name}-{key[:12]}" for _, key in entries))


def capture_sh_basis(scene, camera, *, degree=3, spp=DEFAULT_SH_SPP, cache_dir=None,
                     variant=None, cache=True):
  """Images of the scene lit by each real SH basis function as environment light.

  I_j is the linear radiance image under the environment L(d) = Y_j(d) (d: world direction
  towards the sky; Y from `mfsample.renderer.sh.sh_basis`, same ordering). Y_j is signed, so
  its positive and negative parts are rendered separately and subtracted. Light transport
  is linear, so the image under the SH light L(d) = sum_j xi_j Y_j(d) is `relight(I, xi)`.
  The scene's fixed lights are not used; the background is black (radiance 0).

  Args:
    scene: a `Scene`.
    camera: one unbatched `Camera`.
    degree: SH degree, 0..3.
    spp, cache_dir, variant, cache: as in `capture` (each of the 2 (degree+1)^2 - 1
      renders uses `spp`).

  Returns:
    [(degree + 1)^2, H, W, 3] float32 signed linear radiance.
  """
  if not isinstance(camera, Camera) or camera.batch_shape:
    raise ValueError("capture_sh_basis takes one unbatched Camera")
  if not 0 <= degree <= 3:
    raise ValueError(f"degree must be in 0..3, got {degree}")
  spp = _check_spp(spp)
  variant = bridge.resolve_variant(variant)
  key = cache_lib.capture_key("sh_basis", scene, camera, spp=spp, variant=variant,
                              sampler=bridge.SAMPLER, degree=degree,
                              env=[ENV_HEIGHT, ENV_WIDTH])
  path = cache_lib.entry_path(cache_dir or cache_lib.default_cache_dir(), scene, "sh_basis",
                              key)
  if cache:
    size = (camera.height, camera.width)
    stored = cache_lib.load(path, {"basis": ((degree + 1) ** 2,) + size + (3,)})
    if stored is not None:
      return stored["basis"]
  basis = sh_environment_texels(degree)
  mi_scene = bridge.build_scene(scene, variant,
                                environment=np.ones(basis.shape[1:] + (3,), np.float32))
  mi_sensor = bridge.sensor(camera, spp, variant)
  seed = _seed(key)
  images = np.zeros((len(basis), camera.height, camera.width, 3), np.float32)
  for j, texels in enumerate(basis):
    for part, sign in enumerate((1.0, -1.0)):
      lobe = np.maximum(sign * texels, 0.0)
      if not np.any(lobe > 0):  # e.g. the negative part of Y_0
        continue
      bridge.set_environment(mi_scene, np.repeat(lobe[..., None], 3, axis=-1))
      out = bridge.render(mi_scene, mi_sensor, spp, seed + 2 * j + part)
      images[j] += sign * out["radiance"]
  if cache:
    cache_lib.save(path, {"basis": images})
  return images


def relight(basis_images, xi):
  """The image under the SH light xi from `capture_sh_basis` images.

  Args:
    basis_images: [K, H, W, 3] images I_j.
    xi: [K] (white light) or [K, 3] (per colour channel) SH coefficients.

  Returns:
    [H, W, 3] sum_j xi_j I_j (linear radiance, unclipped).
  """
  basis_images = np.asarray(basis_images)
  xi = np.asarray(xi, basis_images.dtype)
  if xi.ndim == 1:
    xi = np.repeat(xi[:, None], 3, axis=1)
  if xi.shape != (basis_images.shape[0], 3):
    raise ValueError(f"xi must be [K] or [K, 3] with K = {basis_images.shape[0]}, got "
                     f"{xi.shape}")
  return np.einsum("khwc,kc->hwc", basis_images, xi)


def sh_environment_texels(degree, height=ENV_HEIGHT, width=ENV_WIDTH):
  """[(degree + 1)^2, h, w] texels of each SH basis function over world directions."""
  dirs = bridge.texel_directions(height, width)
  values = np.asarray(sh_lib.sh_basis(dirs.astype(np.float32), degree), np.float32)
  return np.moveaxis(values, -1, 0)


# ------------------------------------------------------------------ internals


def _check_spp(spp):
  # Mitsuba's stratified sampler would silently round other counts up to a square.
  if (not isinstance(spp, (int, np.integer)) or isinstance(spp, bool) or spp < 1
      or math.isqrt(spp) ** 2 != spp):
    raise ValueError(f"spp must be a perfect square (1, 4, 9, 16, 25, 36, 64, ...: the "
                     f"stratified sampler's grids), got {spp!r}")
  return int(spp)


def _seed(key):
  """A deterministic per-capture seed, so that views do not share one noise pattern."""
  return int(key[:7], 16)


def _capture_entries(scene, cameras, *, spp, cache_dir, variant, cache, progress):
  """[(entry dict with radiance, alpha, depth; cache key)] for a list of unbatched cameras."""
  spp = _check_spp(spp)
  variant = bridge.resolve_variant(variant)
  root = cache_dir or cache_lib.default_cache_dir()
  mi_scene = None  # built on the first cache miss only: fully cached runs need no Mitsuba
  results = []
  bar = tqdm.tqdm(cameras, desc=f"capture {scene.name}", unit="view", disable=not progress)
  for camera in bar:
    key = cache_lib.capture_key("rgbad", scene, camera, spp=spp, variant=variant,
                                sampler=bridge.SAMPLER)
    path = cache_lib.entry_path(root, scene, "rgbad", key)
    size = (camera.height, camera.width)
    entry = cache_lib.load(path, {"radiance": size + (3,), "alpha": size,
                                  "depth": size}) if cache else None
    if entry is None:
      if mi_scene is None:
        mi_scene = bridge.build_scene(scene, variant)
      out = bridge.render(mi_scene, bridge.sensor(camera, spp, variant), spp, _seed(key))
      entry = {"radiance": out["radiance"], "alpha": out["alpha"],
               "depth": bridge.z_depth(out["position"], out["alpha"], camera)}
      if cache:
        cache_lib.save(path, entry)
    results.append((entry, key))
  return results


def _composite(entry, background):
  bg = np.asarray(background, np.float32)
  if bg.shape != (3,):
    raise ValueError(f"background must be 3 numbers, got {background!r}")
  alpha = entry["alpha"].astype(np.float32)
  rgb = entry["radiance"] + (1.0 - alpha[..., None]) * bg
  return np.clip(rgb, 0.0, 1.0).astype(np.float32), alpha
