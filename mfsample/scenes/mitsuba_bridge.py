"""The Mitsuba 3 side of captures: scene and sensor conversion, rendering, SH environments.

Mitsuba is imported lazily (`require_mitsuba`), so the rest of `mfsample.scenes` works
without it. Conventions bridged here:

* Cameras: Mitsuba's perspective sensor looks down its local +z with +y up and +x to the
  *left*; OpenCV looks down +z with y down and x right. So sensor-to-world =
  camera-to-world (OpenCV) @ diag(-1, -1, 1). `fov_axis='x'` gives fx; the principal point
  is `principal_point_offset_{x,y}` in units of the film width / height, positive towards
  smaller pixel coordinates: cx = W / 2 - offset_x W (measured: tests/scenes/test_scenes.py).
  Mitsuba's film pixel (i, j) covers [j, j + 1) x [i, i + 1) like ours; a box
  reconstruction filter keeps each sample inside its pixel, so alpha is exact coverage.
* Depth: the `aov` integrator's `position` output is the coverage-weighted mean of the hit
  points, which is linear in the hit, so z = ((P - A o) . forward) / A is the mean camera
  z-depth of the hits, exact per sample (Mitsuba's `depth` AOV is ray length, not z).
* Environment maps (`envmap`): a local direction (x, y, z) has u = atan2(x, -z) / 2 pi and
  v = acos(y) / pi; texel column c sits at u = (c + 1/2) / W and row r at v = r / (H - 1)
  (rows include both poles); radiance is bilinear between texels (checked against
  `Emitter.eval` in tests/scenes/test_scenes.py). We rotate local +y to world +z (`ENV_TO_WORLD`)
  and fill texels with our function of the *world* direction. Mitsuba 3.9 stores the texels
  with one wrap-around column on each side; `set_environment` writes that layout.
"""

import functools
import os
import subprocess
import sys

import numpy as np

SUPPORTED_VARIANTS = ("scalar_rgb", "llvm_ad_rgb")
DEFAULT_VARIANT = "scalar_rgb"
VARIANT_ENV = "MFSAMPLE_MITSUBA_VARIANT"

# Sampler of every capture: stratified (jittered grid) per pixel, about 2x lower RMSE than
# independent samples at equal spp; it needs a perfect-square sample count.
SAMPLER = "stratified"

# Envmap local -> world rotation: local +y (Mitsuba's envmap "up") to world +z; columns are
# the images of the local x, y, z axes (x -> x, y -> z, z -> -y).
ENV_TO_WORLD = np.array([[1.0, 0.0, 0.0],
                         [0.0, 0.0, -1.0],
                         [0.0, 1.0, 0.0]])

# OpenCV camera axes -> Mitsuba sensor axes (x left, y up, z forward).
_CV_TO_MITSUBA = np.diag([-1.0, -1.0, 1.0, 1.0])

INSTALL_HINT = ('Captures need Mitsuba 3: pip install "mfsample[scenes]" '
                '(or pip install mitsuba).')


def require_mitsuba():
  """Imports and returns the `mitsuba` module, or raises ImportError with the install hint."""
  try:
    import mitsuba  # the optional extra, imported on first use only
  except ImportError as e:
    raise ImportError(INSTALL_HINT) from e
  return mitsuba


def mitsuba_available():
  """True when `import mitsuba` works (without importing it twice)."""
  try:
    require_mitsuba()
  except ImportError:
    return False
  return True


@functools.cache
def llvm_available():
  """Whether the `llvm_ad_rgb` variant can render here.

  It needs the LLVM shared library at run time (Debian: `apt-get install libllvm19`; set
  DRJIT_LIBLLVM_PATH if Dr.Jit picks an older one). A too-old LLVM aborts the process while
  compiling, so the check renders a tiny scene in a subprocess. Cached per process.
  """
  if not mitsuba_available():
    return False
  probe = ("import mitsuba as mi; mi.set_variant('llvm_ad_rgb'); "
           "s = mi.load_dict({'type': 'scene', 'integrator': {'type': 'path'}, "
           "'sphere': {'type': 'sphere'}, 'light': {'type': 'constant'}, "
           "'sensor': {'type': 'perspective', 'film': {'type': 'hdrfilm', 'width': 4, "
           "'height': 4}}}); print(float(mi.render(s, spp=1).numpy().sum()))")
  try:
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, timeout=120,
                            check=False)
  except (OSError, subprocess.TimeoutExpired):
    return False
  return result.returncode == 0


def resolve_variant(variant=None):
  """The Mitsuba variant to use: the argument, else $MFSAMPLE_MITSUBA_VARIANT, else
  "scalar_rgb". "auto" means "llvm_ad_rgb" when `llvm_available()`, else "scalar_rgb"."""
  if variant is None:
    variant = os.environ.get(VARIANT_ENV) or DEFAULT_VARIANT
  if variant == "auto":
    variant = "llvm_ad_rgb" if llvm_available() else "scalar_rgb"
  if variant not in SUPPORTED_VARIANTS:
    raise ValueError(f"Mitsuba variant must be one of {SUPPORTED_VARIANTS} or 'auto', got "
                     f"{variant!r}")
  return variant


def set_variant(variant):
  """Selects `variant` (global Mitsuba state; every capture sets it before building)."""
  mi = require_mitsuba()
  if variant not in mi.variants():
    raise ImportError(f"this Mitsuba build has no {variant!r} variant "
                      f"(available: {', '.join(mi.variants())}).")
  mi.set_variant(variant)
  return mi


# ------------------------------------------------------------------ scene conversion


def build_scene(scene, variant, *, environment=None, visible_environment=False):
  """Loads a `Scene` description into Mitsuba.

  Args:
    scene: `mfsample.scenes.Scene`.
    variant: a supported variant name.
    environment: None for the scene's own `Lighting`; otherwise [h, w, 3] float32 radiance
      texels in Mitsuba's lat-long layout (see `environment_texels`), used as the only light.
    visible_environment: show the lights to camera rays (tests of the envmap mapping);
      captures hide them so that the background is empty (alpha = 0, radiance 0).

  Returns:
    a `mitsuba.Scene`.
  """
  mi = set_variant(variant)
  desc = {"type": "scene"}
  desc["integrator"] = {
      "type": "aov",
      "aovs": "pos:position",
      "radiance": {"type": "path", "max_depth": int(scene.max_depth),
                   "hide_emitters": not visible_environment},
  }
  for shape in scene.shapes:
    desc[shape.name] = _shape(mi, shape)
  if environment is None:
    light = scene.lighting
    if light.ambient > 0:
      desc["sky"] = {"type": "constant",
                     "radiance": {"type": "rgb", "value": [float(light.ambient)] * 3}}
    if light.sun_irradiance > 0:
      direction = -np.asarray(light.sun_direction, np.float64)
      desc["sun"] = {"type": "directional", "direction": (direction / np.linalg.norm(
          direction)).tolist(), "irradiance": {"type": "rgb",
                                               "value": [float(light.sun_irradiance)] * 3}}
  else:
    texels = np.ascontiguousarray(environment, dtype=np.float32)
    if texels.ndim != 3 or texels.shape[-1] != 3 or np.any(texels < 0):
      raise ValueError(f"environment must be non-negative [h, w, 3], got {texels.shape}")
    to_world = np.eye(4)
    to_world[:3, :3] = ENV_TO_WORLD
    desc["environment"] = {"type": "envmap", "bitmap": mi.Bitmap(texels),
                           "to_world": mi.ScalarTransform4f(to_world.tolist())}
  return mi.load_dict(desc)


def _bsdf(material):
  if material.checker is not None:
    reflectance = {"type": "checkerboard",
                   "color0": {"type": "rgb", "value": list(material.color)},
                   "color1": {"type": "rgb", "value": list(material.checker)},
                   "to_uv": _uv_scale(material.tiles)}
  else:
    reflectance = {"type": "rgb", "value": list(material.color)}
  if material.kind == "diffuse":
    return {"type": "diffuse", "reflectance": reflectance}
  if material.kind == "plastic":
    return {"type": "roughplastic", "distribution": "ggx", "alpha": float(material.roughness),
            "diffuse_reflectance": reflectance}
  return {"type": "roughconductor", "material": material.metal, "distribution": "ggx",
          "alpha": float(material.roughness),
          "specular_reflectance": {"type": "rgb", "value": list(material.color)}}


def _uv_scale(tiles):
  # Mitsuba's checkerboard has 2 x 2 squares per unit of uv.
  mi = require_mitsuba()
  return mi.ScalarTransform4f().scale([0.5 * tiles, 0.5 * tiles, 1.0])


def _shape(mi, shape):
  bsdf = mi.load_dict(_bsdf(shape.material))
  if not shape.is_mesh:
    return {"type": shape.kind, "to_world": mi.ScalarTransform4f(shape.to_world().tolist()),
            "bsdf": bsdf}
  mesh = shape.mesh()
  props = mi.Properties()
  props["bsdf"] = bsdf
  out = mi.Mesh(shape.name, len(mesh.vertices), len(mesh.faces), props=props,
                has_vertex_normals=True, has_vertex_texcoords=True)
  params = mi.traverse(out)
  for key, value in (("vertex_positions", mesh.vertices), ("vertex_normals", mesh.normals),
                     ("vertex_texcoords", mesh.uvs), ("faces", mesh.faces)):
    params[key] = type(params[key])(np.ravel(value))
  params.update()
  return out


def sensor(camera, spp, variant):
  """A Mitsuba perspective sensor (box-filtered film, `SAMPLER`) for one `mfsample.Camera`.

  Raises:
    ValueError: non-square pixels (fx != fy), which Mitsuba's perspective sensor lacks.
  """
  mi = set_variant(variant)
  if camera.batch_shape:
    raise ValueError(f"one camera expected, got a batch {camera.batch_shape}")
  fx, fy = float(camera.fx), float(camera.fy)
  if abs(fx - fy) > 1e-5 * max(fx, fy):
    raise ValueError(f"Mitsuba captures need square pixels (fx == fy), got fx={fx}, fy={fy}.")
  width, height = camera.width, camera.height
  w2c = np.asarray(camera.world_to_camera, np.float64)
  rot = w2c[:3, :3]
  c2w = np.eye(4)
  c2w[:3, :3] = rot.T
  c2w[:3, 3] = -rot.T @ w2c[:3, 3]
  # Re-orthonormalise: float32 rotations are off by ~1e-7 and Mitsuba rejects scaled sensors.
  u, _, vt = np.linalg.svd(c2w[:3, :3])
  c2w[:3, :3] = u @ vt
  return mi.load_dict({
      "type": "perspective",
      "fov_axis": "x",
      "fov": float(np.degrees(2.0 * np.arctan(0.5 * width / fx))),
      "principal_point_offset_x": (0.5 * width - float(camera.cx)) / width,
      "principal_point_offset_y": (0.5 * height - float(camera.cy)) / height,
      "near_clip": 1e-3,
      "far_clip": 1e4,
      "to_world": mi.ScalarTransform4f((c2w @ _CV_TO_MITSUBA).tolist()),
      "film": {"type": "hdrfilm", "width": width, "height": height,
               "rfilter": {"type": "box"}, "pixel_format": "rgba",
               "sample_border": False},
      "sampler": {"type": SAMPLER, "sample_count": int(spp)},
  })


def render(mi_scene, mi_sensor, spp, seed):
  """Renders one view.

  Returns:
    dict of float32 numpy arrays: `radiance` [H, W, 3] premultiplied linear RGB (0 where
    nothing was hit), `alpha` [H, W] hit fraction, `position` [H, W, 3] coverage-weighted
    mean world position of the hits.
  """
  mi = require_mitsuba()
  image = np.array(mi.render(mi_scene, sensor=mi_sensor, spp=int(spp), seed=int(seed)),
                   dtype=np.float32)
  if image.shape[-1] != 7:  # R, G, B, A, then the position AOV
    raise RuntimeError(f"unexpected Mitsuba output with {image.shape[-1]} channels")
  return {"radiance": image[..., :3], "alpha": image[..., 3], "position": image[..., 4:7]}


def z_depth(position, alpha, camera):
  """Mean camera z-depth of the hits from the position AOV (see the module docstring).

  Args:
    position: [H, W, 3] coverage-weighted mean world position (0 where nothing was hit).
    alpha: [H, W] hit fraction.
    camera: the unbatched `Camera` it was rendered with.

  Returns:
    [H, W] float32 z-depth, 0 where alpha == 0.
  """
  w2c = np.asarray(camera.world_to_camera, np.float64)
  forward = w2c[2, :3]  # the camera's z axis in world coordinates
  origin = -w2c[:3, :3].T @ w2c[:3, 3]
  a = np.asarray(alpha, np.float64)
  num = np.asarray(position, np.float64) @ forward - a * float(origin @ forward)
  hit = a > 0
  return np.where(hit, num / np.where(hit, a, 1.0), 0.0).astype(np.float32)


# ------------------------------------------------------------------ environments


def set_environment(mi_scene, texels):
  """Replaces the envmap radiance of a scene built with `environment=` (no rebuild: the BVH
  and the meshes are kept, only the envmap's sampling distribution is recomputed)."""
  mi = require_mitsuba()
  texels = np.ascontiguousarray(texels, dtype=np.float32)
  params = mi.traverse(mi_scene)
  current = params["environment.data"].shape
  padded = np.concatenate([texels[:, -1:], texels, texels[:, :1]], axis=1)
  if tuple(current) != padded.shape:
    raise RuntimeError(f"unexpected envmap layout {tuple(current)} for texels "
                       f"{texels.shape} (Mitsuba version change?)")
  params["environment.data"] = mi.TensorXf(padded)
  params.update()


def texel_directions(height, width):
  """[h, w, 3] world directions at the texels of a Mitsuba lat-long envmap (`ENV_TO_WORLD`)."""
  theta = np.pi * np.arange(height) / (height - 1)
  phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
  theta, phi = np.meshgrid(theta, phi, indexing="ij")
  local = np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)],
                   axis=-1)
  return local @ ENV_TO_WORLD.T


def environment_texels(fn, height=64, width=128):
  """Texels [h, w, 3] of the envmap whose radiance towards world direction d is fn(d).

  Args:
    fn: maps [..., 3] unit world directions to [...] or [..., 3] radiance.
    height, width: lat-long resolution (radiance is bilinear in between).
  """
  values = np.asarray(fn(texel_directions(height, width)), np.float32)
  if values.ndim == 2:
    values = np.repeat(values[..., None], 3, axis=-1)
  return values
