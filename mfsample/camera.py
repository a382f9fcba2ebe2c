"""Pinhole cameras in OpenCV axes.

Conventions (shared by the renderer, the dataset loaders and the capture oracle):

* camera axes: x right, y down, z forward (OpenCV);
* `world_to_camera` maps homogeneous world points to camera coordinates;
* a point (x, y, z) in camera axes lands at pixel coordinates
  (u, v) = (fx x / z + cx, fy y / z + cy);
* pixel (row i, column j) is the unit square [j, j + 1) x [i, i + 1) and is sampled at its
  centre (j + 0.5, i + 0.5). A centred principal point is therefore cx = width / 2.

A `Camera` is a pytree: `world_to_camera`, `fx`, `fy`, `cx`, `cy` are differentiable leaves
(with optional leading batch axes, so a batch of cameras is one `Camera`), `width` and
`height` are static metadata.

Validity. A camera is *valid* when its pose is finite and rigid (a rotation: R^T R = I and
det R = +1 within `RIGID_TOLERANCE`, so neither scaled, sheared nor reflected; bottom row
[0, 0, 0, 1]), its translation within `mfsample.numerics.WORLD_LIMIT` (1e18) world units, and
its intrinsics are finite with fx, fy > 0.

* Eagerly (concrete values), the constructors `create`, `look_at` and `from_blender` raise
  `InvalidCameraError` naming the field, the batch index and what is wrong.
* Under `jit`, `vmap` or `grad` the values are unknown when the constructors run, so they
  check nothing (no host sync, nothing that breaks tracing). `camera.valid` is the same test
  as a boolean array of the batch shape, for jitted callers to branch on, and `render`
  returns NaN images for an invalid camera, so that every finiteness check downstream
  catches it (see `mfsample.renderer.render`).
* The plain constructor `Camera(...)` checks shapes only: JAX also calls it to rebuild
  cameras whose leaves are not poses (gradients, tangents, `jax.tree.map` results).

Why a flag and not `checkify`: a `checkify.check` inside a jitted function fails to trace
unless every caller up the stack wraps its function with `checkify.checkify`, which the
pose optimisation, the candidate scoring and the training step (and user code) would all
have to do; a boolean is free, composes with `vmap`, and NaN images reach the checks that
already exist.
"""

import math

import chex
import jax
import jax.numpy as jnp
import numpy as np

from mfsample import numerics
from mfsample._pytree import pytree_dataclass, static_field

# Blender / OpenGL camera axes (x right, y up, z backward) -> OpenCV axes.
_GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])

# A pose is rigid when max |R^T R - I|, |det R - 1| and the bottom row's distance to
# [0, 0, 0, 1] stay below this. Poses stored or composed in float32 are rigid to ~1e-6; a
# scale of 1.001 or a shear of 1e-3 is not. (The dataset loaders use the same tolerance.)
RIGID_TOLERANCE = 1e-3


class InvalidCameraError(ValueError):
  """A camera with a non-finite or non-rigid pose, or non-finite or non-positive intrinsics."""


@pytree_dataclass
class Camera:
  """A pinhole camera (see the module docstring for the conventions).

  Attributes:
    world_to_camera: [..., 4, 4] rigid transform, world -> camera (OpenCV axes).
    fx, fy: [...] focal lengths in pixels.
    cx, cy: [...] principal point in pixels (continuous coordinates).
    width, height: image size in pixels (static).
  """

  world_to_camera: chex.Array
  fx: chex.Array
  fy: chex.Array
  cx: chex.Array
  cy: chex.Array
  width: int = static_field()
  height: int = static_field()

  def __post_init__(self):
    # Runs at construction, i.e. at trace time under jit: shape errors surface early.
    for name in ("width", "height"):
      value = getattr(self, name)
      if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
        raise ValueError(f"Camera.{name} must be an integer >= 1, got {value!r}.")
    w2c = self.world_to_camera
    if hasattr(w2c, "shape") and tuple(w2c.shape[-2:]) != (4, 4):
      raise ValueError(f"Camera.world_to_camera must have shape [..., 4, 4], got {w2c.shape}.")

  # ---------------------------------------------------------------- constructors

  @classmethod
  def create(cls, world_to_camera, fx, fy, cx, cy, width, height):
    """Builds a camera from arrays, broadcasting the intrinsics to the batch shape.

    Raises:
      InvalidCameraError: for concrete values that are not a valid camera (see the module
        docstring); traced values are not checked (test `camera.valid`).
    """
    w2c = jnp.asarray(world_to_camera)
    if not jnp.issubdtype(w2c.dtype, jnp.floating):
      w2c = w2c.astype(jnp.float32)
    if w2c.ndim < 2 or tuple(w2c.shape[-2:]) != (4, 4):
      raise ValueError(f"Camera.world_to_camera must have shape [..., 4, 4], got {w2c.shape}.")
    batch = w2c.shape[:-2]

    def intrinsic(name, v):
      v = jnp.asarray(v, dtype=w2c.dtype)
      try:
        return jnp.broadcast_to(v, batch)
      except ValueError:
        raise ValueError(f"Camera.{name} of shape {v.shape} does not broadcast to the pose's "
                         f"batch shape {batch}.") from None

    as_int = lambda v: int(v) if isinstance(v, np.integer) else v  # validated on init
    camera = cls(w2c, intrinsic("fx", fx), intrinsic("fy", fy), intrinsic("cx", cx),
                 intrinsic("cy", cy), as_int(width), as_int(height))
    if _is_concrete(camera):
      camera.validate()
    return camera

  @classmethod
  def look_at(cls, eye, target, up, fov_x, width, height):
    """A camera at `eye` looking at `target`, with `up` pointing up in the image.

    Differentiable w.r.t. `eye`, `target` and `fov_x` (radians, horizontal field of view).
    Accepts batched `eye` / `target` ([..., 3]). Square pixels, centred principal point.
    When the viewing direction is parallel to `up`, a perpendicular fallback up vector is
    used instead of producing NaNs.
    """
    eye = jnp.asarray(eye, dtype=jnp.result_type(float, eye))
    target = jnp.asarray(target, dtype=eye.dtype)
    up = jnp.asarray(up, dtype=eye.dtype)
    _check_look_at(eye, target, up)
    up = jnp.broadcast_to(up, jnp.broadcast_shapes(eye.shape, target.shape))
    forward = numerics.safe_normalize(target - eye, fallback=jnp.array([0.0, 0.0, 1.0]))
    right = jnp.cross(forward, up)
    # Fallback for forward || up: any axis not parallel to forward.
    alt_up = jnp.where(jnp.abs(forward[..., :1]) < 0.9, jnp.array([1.0, 0.0, 0.0]),
                       jnp.array([0.0, 1.0, 0.0]))
    degenerate = jnp.sum(right * right, axis=-1, keepdims=True) < 1e-12
    right = jnp.where(degenerate, jnp.cross(forward, alt_up), right)
    right = numerics.safe_normalize(right)
    down = jnp.cross(forward, right)
    rotation = jnp.stack([right, down, forward], axis=-2)  # rows: camera axes in world
    translation = -jnp.einsum("...ij,...j->...i", rotation, eye)
    w2c = _compose(rotation, translation)
    _check_fov("fov_x", fov_x)
    fx = 0.5 * width / jnp.tan(0.5 * jnp.asarray(fov_x, dtype=eye.dtype))
    return cls.create(w2c, fx, fx, 0.5 * width, 0.5 * height, width, height)

  @classmethod
  def from_blender(cls, c2w, camera_angle_x, width, height):
    """A camera from a NeRF Synthetic `transform_matrix` (camera-to-world, OpenGL axes).

    Args:
      c2w: [..., 4, 4] (or [..., 3, 4]) camera-to-world in Blender/OpenGL axes.
      camera_angle_x: horizontal field of view in radians.
      width, height: image size in pixels.
    """
    c2w = jnp.asarray(c2w, dtype=jnp.result_type(float, c2w))
    if c2w.ndim < 2 or tuple(c2w.shape[-2:]) not in ((3, 4), (4, 4)):
      raise ValueError(f"Camera.from_blender: c2w must have shape [..., 4, 4] or [..., 3, 4], "
                       f"got {list(c2w.shape)}")
    if c2w.shape[-2] == 3:
      bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0], c2w.dtype),
                                c2w.shape[:-2] + (1, 4))
      c2w = jnp.concatenate([c2w, bottom], axis=-2)
    c2w_cv = c2w @ jnp.asarray(_GL_TO_CV, dtype=c2w.dtype)
    rotation = jnp.swapaxes(c2w_cv[..., :3, :3], -1, -2)
    translation = -jnp.einsum("...ij,...j->...i", rotation, c2w_cv[..., :3, 3])
    _check_fov("camera_angle_x", camera_angle_x)
    fx = 0.5 * width / math.tan(0.5 * float(camera_angle_x))
    return cls.create(_compose(rotation, translation), fx, fx, 0.5 * width, 0.5 * height,
                      width, height)

  # ---------------------------------------------------------------- validity

  @property
  def valid(self):
    """[...] bool: finite, rigid pose within `numerics.WORLD_LIMIT` of the origin, and finite
    intrinsics with fx, fy > 0.

    Pure jnp, so it works under jit / vmap / grad (no gradient flows through it).
    """
    w2c = self.world_to_camera
    rot = w2c[..., :3, :3]
    eye = jnp.eye(3, dtype=w2c.dtype)
    ortho = jnp.max(jnp.abs(jnp.swapaxes(rot, -1, -2) @ rot - eye), axis=(-2, -1))
    bottom = jnp.max(jnp.abs(w2c[..., 3, :] - jnp.array([0.0, 0.0, 0.0, 1.0], w2c.dtype)),
                     axis=-1)
    det = jnp.linalg.det(rot)
    finite = jnp.all(jnp.isfinite(w2c), axis=(-2, -1))
    finite = finite & jnp.all(jnp.abs(w2c[..., :3, 3]) <= numerics.WORLD_LIMIT, axis=-1)
    intrinsics = [self.fx, self.fy, self.cx, self.cy]
    finite = finite & jnp.all(jnp.stack([jnp.isfinite(v) for v in intrinsics]), axis=0)
    # Comparisons with NaN are False, so a non-finite pose also fails the rigidity tests.
    rigid = (ortho <= RIGID_TOLERANCE) & (jnp.abs(det - 1.0) <= RIGID_TOLERANCE) & (
        bottom <= RIGID_TOLERANCE)
    return jax.lax.stop_gradient(finite & rigid & (self.fx > 0) & (self.fy > 0))

  def problems(self):
    """What makes this (concrete) camera invalid: a list of messages, empty when valid.

    Each message names the field and, for a batch, the first offending index. Host numpy
    in float64; it syncs, so call it on concrete cameras only (not under jit).
    """
    w2c = np.asarray(self.world_to_camera, np.float64)
    batch = w2c.shape[:-2]
    finite = np.all(np.isfinite(w2c), axis=(-2, -1))
    safe = np.where(finite[..., None, None], w2c, np.eye(4))  # rigidity of finite poses only
    rot = safe[..., :3, :3]
    ortho = np.max(np.abs(np.swapaxes(rot, -1, -2) @ rot - np.eye(3)), axis=(-2, -1))
    det = np.linalg.det(rot)
    bottom = np.max(np.abs(safe[..., 3, :] - [0.0, 0.0, 0.0, 1.0]), axis=-1)
    out = []

    def report(bad, message):
      """Appends `message(index, where)` for the first index where `bad` holds."""
      bad = np.broadcast_to(bad, batch)
      if np.any(bad):
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        where = f"[{', '.join(map(str, index))}]" if batch else ""
        out.append(message(index, where))

    report(~finite, lambda i, at: f"Camera.world_to_camera{at} has non-finite entries")
    far = finite & np.any(np.abs(safe[..., :3, 3]) > numerics.WORLD_LIMIT, axis=-1)
    report(far, lambda i, at: (
        f"Camera.world_to_camera{at} has the translation "
        f"[{', '.join(f'{v:.4g}' for v in safe[i][:3, 3])}], out of "
        f"range: the camera must sit within {numerics.WORLD_LIMIT:g} world units of the "
        "origin (float32 squares of larger distances overflow)"))
    report(bottom > RIGID_TOLERANCE, lambda i, at: (
        f"Camera.world_to_camera{at} has bottom row {w2c[i][3].tolist()}, expected "
        "[0, 0, 0, 1]"))
    report(det < 0, lambda i, at: (
        f"Camera.world_to_camera{at} is a reflection (det R = {det[i]:.4f} < 0), not a "
        "right-handed rotation"))
    report((det >= 0) & ((ortho > RIGID_TOLERANCE) | (np.abs(det - 1.0) > RIGID_TOLERANCE)),
           lambda i, at: (f"Camera.world_to_camera{at} is not rigid (|R^T R - I| = "
                          f"{ortho[i]:.2e}, det R = {det[i]:.4f}; tolerance "
                          f"{RIGID_TOLERANCE})"))
    for name in ("fx", "fy", "cx", "cy"):
      v = np.broadcast_to(np.asarray(getattr(self, name), np.float64), batch)
      report(~np.isfinite(v), lambda i, at, name=name: f"Camera.{name}{at} is not finite")
      if name in ("fx", "fy"):
        report(v <= 0, lambda i, at, name=name, v=v: (
            f"Camera.{name}{at} = {v[i]} must be > 0 (a focal length in pixels)"))
    return out

  def validate(self):
    """Raises `InvalidCameraError` listing `problems()`; returns the camera when valid."""
    problems = self.problems()
    if problems:
      raise InvalidCameraError("invalid camera: " + "; ".join(problems) + ".")
    return self

  # ---------------------------------------------------------------- derived values

  @property
  def rotation(self):
    """[..., 3, 3] world -> camera rotation."""
    return self.world_to_camera[..., :3, :3]

  @property
  def translation(self):
    """[..., 3] world -> camera translation."""
    return self.world_to_camera[..., :3, 3]

  @property
  def center(self):
    """[..., 3] camera centre in world coordinates (-R^T t)."""
    return -jnp.einsum("...ji,...j->...i", self.rotation, self.translation)

  @property
  def camera_to_world(self):
    """[..., 4, 4] inverse of `world_to_camera` (assumed rigid)."""
    rot_t = jnp.swapaxes(self.rotation, -1, -2)
    return _compose(rot_t, self.center)

  @property
  def batch_shape(self):
    return tuple(self.world_to_camera.shape[:-2])

  def __getitem__(self, index):
    """Indexes the batch axes: `cameras[3]`, `cameras[:5]`."""
    return Camera(self.world_to_camera[index], self.fx[index], self.fy[index],
                  self.cx[index], self.cy[index], self.width, self.height)

  def __len__(self):
    if not self.batch_shape:
      raise TypeError("len() of an unbatched Camera")
    return self.batch_shape[0]

  def world_to_camera_points(self, points):
    """[..., P, 3] world points -> camera coordinates (same batch axes as the camera)."""
    return (jnp.einsum("...ij,...pj->...pi", self.rotation, points)
            + self.translation[..., None, :])

  def project(self, points):
    """[..., P, 3] world points -> ([..., P, 2] pixel coordinates (u, v), [..., P] depth z).

    Pixel coordinates are continuous: pixel (i, j) is centred at (j + 0.5, i + 0.5).
    Points at or behind the camera get non-finite-free but meaningless coordinates; check
    the returned depth.
    """
    cam = self.world_to_camera_points(points)
    z = cam[..., 2]
    z_safe = jnp.where(jnp.abs(z) > 1e-12, z, 1e-12)
    u = self.fx[..., None] * cam[..., 0] / z_safe + self.cx[..., None]
    v = self.fy[..., None] * cam[..., 1] / z_safe + self.cy[..., None]
    return jnp.stack([u, v], axis=-1), z


def _check_fov(name, fov):
  """A concrete field of view must be a number in (0, pi) radians (traced ones pass)."""
  if isinstance(fov, jax.core.Tracer):
    return
  try:
    values = np.asarray(fov, np.float64)
  except (TypeError, ValueError):
    raise ValueError(f"{name} = {fov!r} must be a number (radians).") from None
  if not np.all((values > 0) & (values < math.pi)):
    raise ValueError(f"{name} = {fov!r} must be in (0, pi) radians (degrees given?).")


def _check_look_at(eye, target, up):
  """Shapes: [..., 3] each, batches that broadcast. Concrete values: finite `eye` and `target`
  within `numerics.WORLD_LIMIT`, a finite, non-zero `up`. A NaN `up` or a far eye would
  otherwise surface as a "not rigid" pose, and a zero `up` would silently take a fallback
  axis."""
  for name, v in (("eye", eye), ("target", target), ("up", up)):
    if v.ndim < 1 or v.shape[-1] != 3:
      raise ValueError(f"Camera.look_at: {name} must have shape [..., 3], got {list(v.shape)}")
  try:
    np.broadcast_shapes(eye.shape, target.shape, up.shape)
  except ValueError:
    raise ValueError(f"Camera.look_at: the batch shapes of eye {list(eye.shape)}, target "
                     f"{list(target.shape)} and up {list(up.shape)} do not broadcast") from None
  for name, v in (("eye", eye), ("target", target)):
    # Checked as points, not only as the pose they make: a far eye squares to inf in
    # float32 and would be reported as a pose that is "not rigid".
    if isinstance(v, jax.core.Tracer):
      continue
    values = np.asarray(v, np.float64)
    if not np.all(np.isfinite(values)):
      raise InvalidCameraError(f"Camera.look_at: {name} has non-finite entries "
                               f"({values.tolist() if values.size <= 12 else 'a batch'})")
    if np.any(np.abs(values) > numerics.WORLD_LIMIT):
      worst = float(np.max(np.abs(values)))
      raise InvalidCameraError(
          f"Camera.look_at: {name} is out of range (a coordinate of magnitude {worst:g}); "
          f"positions must lie within {numerics.WORLD_LIMIT:g} world units of the origin "
          "(float32 squares of larger distances overflow)")
  if isinstance(up, jax.core.Tracer):
    return
  values = np.asarray(up, np.float64).reshape(-1, 3)
  if not np.all(np.isfinite(values)):
    raise InvalidCameraError(f"Camera.look_at: up = {np.asarray(up).tolist()} is not finite")
  if np.any(np.linalg.norm(values, axis=-1) == 0.0):
    raise InvalidCameraError("Camera.look_at: up is a zero vector; it must give the image's "
                             "up direction")


def _is_concrete(camera):
  """True when no leaf of `camera` is a tracer (construction outside jit / vmap / grad)."""
  return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(camera))


def _compose(rotation, translation):
  """[..., 3, 3], [..., 3] -> [..., 4, 4] homogeneous transform."""
  top = jnp.concatenate([rotation, translation[..., :, None]], axis=-1)
  bottom = jnp.broadcast_to(jnp.array([0.0, 0.0, 0.0, 1.0], dtype=rotation.dtype),
                            rotation.shape[:-2] + (1, 4))
  return jnp.concatenate([top, bottom], axis=-2)
