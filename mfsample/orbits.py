"""Cameras around a target: one on an orbit, or a sphere of them (jnp: they jit and vmap).

A camera at azimuth a and elevation e (radians) around `target`, at `distance` from it,

  eye = target + distance (cos e cos a, cos e sin a, sin e),

looks at `target` with +z up in the image: `orbit_camera`. Its inputs may be
traced, so `jax.vmap(lambda a: orbit_camera(a, 0.3, width=64, height=64))(azimuths)` is a
batch of cameras, and the pose is differentiable w.r.t. the angles. `sphere_cameras` places
`num` of them evenly by area over a band of elevations (a Fibonacci spiral), the candidate
sets of next-view selection.
"""

import math

import jax
import jax.numpy as jnp

from mfsample import arg_checks
from mfsample.camera import Camera


def orbit_camera(azimuth: float | jax.Array, elevation: float | jax.Array, *, width: int,
                 height: int, distance: float | jax.Array = 3.5, target: tuple = (0.0, 0.0, 0.0),
                 fov_x: float = 0.9, up: tuple = (0.0, 0.0, 1.0)) -> Camera:
  """The camera at (`azimuth`, `elevation`) around `target`, looking at it.

  Args:
    azimuth: scalar (radians), may be traced; vmap it for a batch.
    elevation: scalar (radians) above the xy-plane, may be traced.
    width, height: image size in pixels (static).
    distance: scalar distance from `target` (world units).
    target: [3] the point looked at.
    fov_x: horizontal field of view (radians, in (0, pi)).
    up: [3] the direction that is up in the image (+z: the axis the angles turn about).

  Returns:
    an unbatched `Camera` (batched like the angles when they are arrays).
  """
  dtype = jnp.result_type(float, azimuth, elevation)
  azimuth, elevation = jnp.asarray(azimuth, dtype), jnp.asarray(elevation, dtype)
  direction = jnp.stack([jnp.cos(elevation) * jnp.cos(azimuth),
                         jnp.cos(elevation) * jnp.sin(azimuth), jnp.sin(elevation)], axis=-1)
  target = jnp.asarray(target, dtype)
  eye = target + jnp.asarray(distance, dtype) * direction
  return Camera.look_at(eye, jnp.broadcast_to(target, eye.shape), jnp.asarray(up, dtype),
                        fov_x, width, height)


def sphere_cameras(num: int, *, width: int, height: int, distance: float = 3.5,
                   target: tuple = (0.0, 0.0, 0.0), fov_x: float = 0.9,
                   elevation_range: tuple = (-0.5 * math.pi, 0.5 * math.pi),
                   up: tuple = (0.0, 0.0, 1.0)) -> Camera:
  """`num` cameras evenly by area over a band of elevations around `target` (a Fibonacci
  spiral), each looking at it.

  Args:
    num: number of cameras (static).
    width, height, distance, target, fov_x, up: as `orbit_camera`.
    elevation_range: (low, high) elevations (radians) of the band; the poles themselves are
      never reached (cameras sit at the centres of equal-area cells).

  Returns:
    a `Camera` batched over [num].
  """
  num = arg_checks.check_int("num", num, minimum=1)
  low, high = (arg_checks.check_float(f"elevation_range[{i}]", e, minimum=-0.5 * math.pi,
                                      maximum=0.5 * math.pi)
               for i, e in enumerate(elevation_range))
  if not low < high:
    raise ValueError(f"elevation_range must be (low, high) with low < high, got "
                     f"{tuple(elevation_range)}")
  i = jnp.arange(num, dtype=jnp.float32) + 0.5
  # Uniform by area: sin(elevation) uniform over the band.
  sin_e = math.sin(low) + (math.sin(high) - math.sin(low)) * i / num
  elevation = jnp.arcsin(sin_e)
  azimuth = jnp.mod(math.pi * (1.0 + 5.0 ** 0.5) * i, 2.0 * math.pi)
  return orbit_camera(azimuth, elevation, width=width, height=height, distance=distance,
                      target=target, fov_x=fov_x, up=up)
