"""Camera parameterisations for view optimisation: a sphere around the scene, and free 6-DoF.

Spherical (the authors' code). A camera sits on a sphere of fixed radius r
around `center` and looks at it with up = +z, at

  u = azimuth / (2 pi),   v = polar / pi,
  eye = center + r (sin(pi v) cos(2 pi u), sin(pi v) sin(2 pi u), cos(pi v)),

the same convention as `mfsample.scenes.Scene.camera_at`. After every optimiser step u is
wrapped to [0, 1) and v clamped to [v_min, v_max] (the authors: [0.01, 0.46], the upper
hemisphere; `SphereSpec.from_scene` reads it from the scene's `polar_range`). The clamp is a
projection *between* steps (`project_uv`), not part of the camera function: a clamp inside
would zero the gradient at the bound and strand the optimiser there.

6-DoF. A tangent vector xi = (omega, rho) in se(3) moves a base pose,

  world_to_camera = exp(xi^) @ base,

a rigid motion expressed in the base camera's own frame (x right, y down, z forward): rho is
a translation in camera axes, omega a rotation about them. `se3_exp` is the closed form
(Rodrigues for the rotation, the left Jacobian V for the translation) with Taylor expansions
near omega = 0, so values and gradients stay finite at the identity.
"""

import dataclasses
import math

import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks
from mfsample.camera import Camera

_UP = (0.0, 0.0, 1.0)


@dataclasses.dataclass(frozen=True)
class SphereSpec:
  """The camera sphere of the spherical parameterisation (static, hashable).

  Attributes:
    center: [3] point the cameras look at (world units).
    radius: sphere radius (world units).
    v_range: (v_min, v_max), the clamp on v = polar / pi.
    fov_x: horizontal field of view (radians).
    width, height: image size in pixels.
  """

  center: tuple = (0.0, 0.0, 0.0)
  radius: float = 3.0
  v_range: tuple = (0.01, 0.46)
  fov_x: float = math.radians(40.0)
  width: int = 64
  height: int = 64

  def __post_init__(self):
    if len(self.v_range) != 2:
      raise ValueError(f"SphereSpec.v_range must be (v_min, v_max), got {self.v_range!r}")
    lo, hi = self.v_range
    if not 0.0 <= lo < hi <= 1.0:
      raise ValueError(f"v_range must satisfy 0 <= v_min < v_max <= 1, got {self.v_range}")
    arg_checks.check_float("SphereSpec.radius", self.radius, above=0.0)
    if len(self.center) != 3:
      raise ValueError(f"SphereSpec.center must be 3 numbers, got {self.center!r}")
    for i, c in enumerate(self.center):
      arg_checks.check_float(f"SphereSpec.center[{i}]", c)
    arg_checks.check_float("SphereSpec.fov_x", self.fov_x, above=0.0, below=math.pi)
    arg_checks.check_int("SphereSpec.width", self.width, minimum=1)
    arg_checks.check_int("SphereSpec.height", self.height, minimum=1)

  @classmethod
  def from_scene(cls, scene, width, height):
    """The sphere of a `mfsample.scenes.Scene` (its camera distance, fov and polar band)."""
    lo, hi = scene.polar_range
    return cls(center=tuple(float(c) for c in scene.center),
               radius=float(scene.camera_distance), v_range=(lo / math.pi, hi / math.pi),
               fov_x=float(scene.fov_x), width=int(width), height=int(height))

  @classmethod
  def from_cameras(cls, cameras: Camera, center=(0.0, 0.0, 0.0)):
    """A sphere fitted to a pool of cameras looking at `center` (e.g. NeRF Synthetic).

    Radius: the median distance to `center`; v_range: the range of the pool's polar angles;
    fov: from the first camera's focal length.
    """
    centers = np.asarray(cameras.center, np.float64).reshape(-1, 3) - np.asarray(center)
    dist = np.linalg.norm(centers, axis=-1)
    v = np.arccos(np.clip(centers[:, 2] / dist, -1.0, 1.0)) / math.pi
    fx = float(np.asarray(cameras.fx).reshape(-1)[0])
    fov_x = 2.0 * math.atan(0.5 * cameras.width / fx)
    return cls(center=tuple(float(c) for c in center), radius=float(np.median(dist)),
               v_range=(float(v.min()), float(v.max())), fov_x=fov_x,
               width=int(cameras.width), height=int(cameras.height))

  def replace(self, **changes):
    return dataclasses.replace(self, **changes)


# ------------------------------------------------------------------ spherical


def uv_to_direction(uv):
  """[..., 2] (u, v) -> [..., 3] unit direction from the centre to the camera."""
  azimuth = 2.0 * jnp.pi * uv[..., 0]
  polar = jnp.pi * uv[..., 1]
  return jnp.stack([jnp.sin(polar) * jnp.cos(azimuth), jnp.sin(polar) * jnp.sin(azimuth),
                    jnp.cos(polar)], axis=-1)


def spherical_camera(uv, sphere: SphereSpec) -> Camera:
  """Camera(s) at `uv` [..., 2] on `sphere`, looking at its centre with up = +z.

  Differentiable w.r.t. `uv`. Batched like `uv`'s leading axes.
  """
  uv = jnp.asarray(uv)
  _check_last_axis("uv", uv, 2)
  if not jnp.issubdtype(uv.dtype, jnp.floating):
    uv = uv.astype(jnp.float32)
  center = jnp.asarray(sphere.center, uv.dtype)
  eye = center + sphere.radius * uv_to_direction(uv)
  target = jnp.broadcast_to(center, eye.shape)
  return Camera.look_at(eye, target, jnp.asarray(_UP, uv.dtype), sphere.fov_x, sphere.width,
                        sphere.height)


def orbit_camera(uv, reference: Camera, sphere: SphereSpec) -> Camera:
  """The camera at `uv` [2] on `sphere` looking at its centre (up +z) with the intrinsics and
  image size of `reference` (unbatched): a start pose moved along its orbit.
  Differentiable w.r.t. `uv`."""
  pose = spherical_camera(uv, sphere).world_to_camera
  return Camera(pose, reference.fx, reference.fy, reference.cx, reference.cy,
                reference.width, reference.height)


def camera_to_uv(camera: Camera, center=(0.0, 0.0, 0.0)):
  """[..., 2] (u, v) of camera centres around `center` (numpy, u in [0, 1))."""
  arg_checks.check_shape("center", center, (3,))
  arg_checks.check_finite("center", np.asarray(center, np.float64))
  d = np.asarray(camera.center, np.float64) - np.asarray(center, np.float64)
  dist = np.linalg.norm(d, axis=-1)
  polar = np.arccos(np.clip(d[..., 2] / np.maximum(dist, 1e-12), -1.0, 1.0))
  azimuth = np.mod(np.arctan2(d[..., 1], d[..., 0]), 2.0 * math.pi)
  return np.stack([azimuth / (2.0 * math.pi), polar / math.pi], axis=-1)


def angle_to_nearest(cameras: Camera, indices, center=(0.0, 0.0, 0.0)):
  """[B] angle (radians, numpy) between each camera's direction from `center` and that of
  the nearest camera among `cameras[indices]` (0 at those cameras)."""
  d = np.asarray(cameras.center, np.float64) - np.asarray(center, np.float64)
  d /= np.linalg.norm(d, axis=-1, keepdims=True)
  return np.arccos(np.clip((d @ d[np.asarray(indices)].T).max(axis=-1), -1.0, 1.0))


def project_uv(uv, sphere: SphereSpec):
  """Wraps u to [0, 1) and clamps v to `sphere.v_range` (applied after every step)."""
  _check_last_axis("uv", uv, 2)
  u = jnp.mod(uv[..., 0], 1.0)
  v = jnp.clip(uv[..., 1], *sphere.v_range)
  return jnp.stack([u, v], axis=-1)


def random_uv(rng: np.random.Generator, num, sphere: SphereSpec):
  """[num, 2] (u, v) uniform by area over the sphere's polar band (numpy)."""
  lo, hi = (math.pi * v for v in sphere.v_range)
  cos_polar = rng.uniform(math.cos(hi), math.cos(lo), num)
  u = rng.uniform(0.0, 1.0, num)
  return np.stack([u, np.arccos(cos_polar) / math.pi], axis=-1)


def uv_grid(sphere: SphereSpec, num_u, num_v):
  """A latitude-longitude grid of (u, v): ([num_v, num_u, 2], u [num_u], v [num_v]).

  Cell centres: u = (i + 1/2) / num_u, v evenly spaced over `sphere.v_range` (inclusive).
  """
  u = (np.arange(num_u) + 0.5) / num_u
  v = np.linspace(*sphere.v_range, num_v)
  grid = np.stack(np.meshgrid(u, v, indexing="xy"), axis=-1)
  return grid.astype(np.float32), u, v


# ------------------------------------------------------------------ 6-DoF


def hat(w):
  """[..., 3] -> [..., 3, 3] skew-symmetric matrix with hat(w) @ x = cross(w, x)."""
  x, y, z = w[..., 0], w[..., 1], w[..., 2]
  zero = jnp.zeros_like(x)
  return jnp.stack([jnp.stack([zero, -z, y], -1), jnp.stack([z, zero, -x], -1),
                    jnp.stack([-y, x, zero], -1)], axis=-2)


def _exp_coefficients(theta_sq):
  """(sin t / t, (1 - cos t) / t^2, (t - sin t) / t^3) of t = sqrt(theta_sq), safe at 0.

  Below 1e-4 (t < 1e-2) the Taylor series to t^4 is exact to float32 precision; the double
  where keeps the discarded closed form from producing 0/0 in the backward pass.
  """
  small = theta_sq < 1e-4
  t_sq = jnp.where(small, 1.0, theta_sq)
  t = jnp.sqrt(t_sq)
  a = jnp.where(small, 1.0 - theta_sq / 6.0 + theta_sq**2 / 120.0, jnp.sin(t) / t)
  b = jnp.where(small, 0.5 - theta_sq / 24.0 + theta_sq**2 / 720.0, (1.0 - jnp.cos(t)) / t_sq)
  c = jnp.where(small, 1.0 / 6.0 - theta_sq / 120.0 + theta_sq**2 / 5040.0,
                (t - jnp.sin(t)) / (t_sq * t))
  return a, b, c


def se3_exp(xi):
  """[..., 6] tangent vector (omega [3], rho [3]) -> [..., 4, 4] rigid transform exp(xi^)."""
  _check_last_axis("xi", xi, 6)
  omega, rho = xi[..., :3], xi[..., 3:]
  w = hat(omega)
  a, b, c = _exp_coefficients(jnp.sum(omega * omega, axis=-1))
  eye = jnp.eye(3, dtype=xi.dtype)
  ww = w @ w
  rot = eye + a[..., None, None] * w + b[..., None, None] * ww
  left_jacobian = eye + b[..., None, None] * w + c[..., None, None] * ww
  t = jnp.einsum("...ij,...j->...i", left_jacobian, rho)
  top = jnp.concatenate([rot, t[..., None]], axis=-1)
  bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0], xi.dtype), xi.shape[:-1] + (1, 4))
  return jnp.concatenate([top, bottom], axis=-2)


def perturb_camera(camera: Camera, xi) -> Camera:
  """`camera` moved by the tangent vector xi [6] in its own frame: exp(xi^) @ world_to_camera.

  Intrinsics and image size are unchanged; differentiable w.r.t. `xi` and the camera.
  """
  w2c = camera.world_to_camera
  xi = jnp.asarray(xi, w2c.dtype)
  if xi.shape != camera.batch_shape + (6,):
    raise ValueError(f"xi must have shape {list(camera.batch_shape) + [6]} (one tangent vector "
                     f"per camera), got {list(xi.shape)}")
  motion = se3_exp(xi)
  return Camera(motion @ w2c, camera.fx, camera.fy, camera.cx, camera.cy, camera.width,
                camera.height)


def _check_last_axis(name, x, size):
  if np.ndim(x) < 1 or np.shape(x)[-1] != size:
    raise ValueError(f"{name} must have shape [..., {size}], got {list(np.shape(x))}")


def downscale_camera(camera: Camera, factor) -> Camera:
  """The same pose with an image `factor` times smaller (intrinsics scaled to match).

  Pixel centres keep their meaning: the principal point and focal lengths scale by
  1 / factor, so a point lands on the same relative image position.
  """
  factor = int(factor)
  if factor == 1:
    return camera
  w, h = camera.width // factor, camera.height // factor
  if w < 1 or h < 1:
    raise ValueError(f"cannot downscale a {camera.width}x{camera.height} camera by {factor}")
  sx, sy = w / camera.width, h / camera.height
  return Camera(camera.world_to_camera, camera.fx * sx, camera.fy * sy, camera.cx * sx,
                camera.cy * sy, w, h)
