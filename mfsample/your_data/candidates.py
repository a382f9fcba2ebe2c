"""Candidate next views of a capture: poses on a sphere oriented by its cameras.

A capture's world frame is arbitrary (COLMAP's has no "up"), so the sphere is placed from
the training cameras themselves: centred on the scene, with the mean distance of the cameras,
its pole along their mean "up" direction (minus each camera's image y axis, the convention
of nerfstudio's auto-orientation), and candidates on a Fibonacci spiral over the band of
polar angles the training cameras cover. Intrinsics and image size are the first training
camera's.
"""

import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks
from mfsample.camera import Camera


def capture_up(cameras: Camera):
  """[3] unit vector: the mean image-up direction of the cameras in world coordinates."""
  rot = np.asarray(cameras.world_to_camera, np.float64).reshape(-1, 4, 4)[:, :3, :3]
  up = -rot[:, 1, :].mean(axis=0)  # row 1 of R is the camera's y axis (down) in world axes
  norm = np.linalg.norm(up)
  if norm < 1e-6:  # cameras that disagree completely: fall back to +z
    return np.array([0.0, 0.0, 1.0])
  return up / norm


def sphere_candidates(cameras: Camera, center, num):
  """`num` cameras on the sphere that the training `cameras` sit on, looking at `center`.

  Args:
    cameras: the training cameras (batched).
    center: [3] the point the candidates look at (the middle of the scene).
    num: number of candidates.

  Returns:
    a `Camera` batched over [num] with the first training camera's intrinsics.
  """
  if not isinstance(cameras, Camera):
    raise ValueError(f"cameras must be a Camera, got {type(cameras).__name__}")
  arg_checks.check_shape("center", center, (3,))
  center = np.asarray(center, np.float64)
  arg_checks.check_finite("center", center)
  arg_checks.check_int("num", num, minimum=1)
  centers = np.asarray(cameras.center, np.float64).reshape(-1, 3) - center
  if np.any(np.linalg.norm(centers, axis=-1) == 0.0):
    raise ValueError("a training camera sits at `center`: the candidates' sphere needs "
                     "cameras around the point they look at")
  radius = float(np.mean(np.linalg.norm(centers, axis=-1)))
  up = capture_up(cameras)
  # An orthonormal frame (e1, e2, up) and the polar band of the training cameras.
  e1 = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
  e1 /= np.linalg.norm(e1)
  e2 = np.cross(up, e1)
  cos_polar = centers @ up / np.maximum(np.linalg.norm(centers, axis=-1), 1e-12)
  lo, hi = float(cos_polar.min()), float(cos_polar.max())
  i = np.arange(num) + 0.5
  cos_t = hi - (hi - lo) * i / num  # uniform by area over the band
  sin_t = np.sqrt(np.clip(1.0 - cos_t ** 2, 0.0, 1.0))
  azimuth = np.pi * (1.0 + 5.0 ** 0.5) * i
  directions = (sin_t[:, None] * (np.cos(azimuth)[:, None] * e1 + np.sin(azimuth)[:, None] * e2)
                + cos_t[:, None] * up)
  eyes = center + radius * directions
  first = cameras[0] if cameras.batch_shape else cameras
  looks = Camera.look_at(jnp.asarray(eyes, jnp.float32),
                         jnp.broadcast_to(jnp.asarray(center, jnp.float32), eyes.shape),
                         jnp.asarray(up, jnp.float32), 1.0, first.width, first.height)
  ones = jnp.ones((num,), jnp.float32)
  return Camera(looks.world_to_camera, first.fx * ones, first.fy * ones, first.cx * ones,
                first.cy * ones, first.width, first.height)
