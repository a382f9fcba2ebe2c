"""Scene descriptions: plain frozen dataclasses, independent of Mitsuba.

A `Scene` lists shapes (Mitsuba primitives or procedural meshes from `meshes`), their
materials and the fixed lighting of ordinary captures, plus what the camera planners need:
the bounding sphere, the up axis (+z) and the camera sphere. The Mitsuba bridge
(`mfsample.scenes.mitsuba_bridge`) turns a description into a renderable scene; the
description's `fingerprint()` keys the capture cache, so editing a scene invalidates its
cached captures.

Camera parameterisation (the authors' code): cameras sit on a sphere of radius
`camera_distance` around `center`, look at `center` with up = +z, at azimuth a (from +x
towards +y) and polar angle p measured from +z:
eye = center + d (sin p cos a, sin p sin a, cos p).
"""

import dataclasses
import hashlib
import json
import math

import numpy as np

from mfsample.camera import Camera
from mfsample.scenes import meshes

PRIMITIVES = ("sphere", "cube", "rectangle", "disk")
MATERIALS = ("diffuse", "plastic", "conductor")


@dataclasses.dataclass(frozen=True)
class Material:
  """A BSDF.

  Attributes:
    kind: "diffuse" (Lambertian), "plastic" (diffuse base under a rough dielectric coat,
      glossy) or "conductor" (rough metal).
    color: linear RGB: diffuse reflectance (diffuse, plastic) or specular tint (conductor).
    roughness: GGX alpha of the plastic coat or the metal.
    checker: optional second colour; the diffuse reflectance becomes a checkerboard of
      `color` and `checker` (textured material). Not for conductors.
    tiles: checker squares per unit of texture coordinate.
    metal: Mitsuba's conductor preset ("Au", "Cu", "Al", ...), for conductors.
  """

  kind: str = "diffuse"
  color: tuple = (0.5, 0.5, 0.5)
  roughness: float = 0.15
  checker: tuple | None = None
  tiles: float = 8.0
  metal: str = "Au"

  def __post_init__(self):
    if self.kind not in MATERIALS:
      raise ValueError(f"Material.kind must be one of {MATERIALS}, got {self.kind!r}")
    if self.checker is not None and self.kind == "conductor":
      raise ValueError("a checker texture needs a diffuse or plastic material")


@dataclasses.dataclass(frozen=True)
class Shape:
  """One object.

  Attributes:
    name: unique within the scene.
    kind: a Mitsuba primitive ("sphere": unit sphere, "cube": [-1, 1]^3, "rectangle":
      [-1, 1]^2 at z = 0 facing +z, "disk": unit disk facing +z) or a mesh generator of
      `meshes.GENERATORS` ("bowl", "cup", "can", "plate", "torus", "vase").
    material: its `Material`.
    position: [3] translation (world units).
    scale: [3] per-axis scale, applied first.
    rotation: (axis x, y, z, angle in degrees), applied after scaling.
    params: mesh-generator keyword arguments as ((name, value), ...).
  """

  name: str
  kind: str
  material: Material = Material()
  position: tuple = (0.0, 0.0, 0.0)
  scale: tuple = (1.0, 1.0, 1.0)
  rotation: tuple = (0.0, 0.0, 1.0, 0.0)
  params: tuple = ()

  def __post_init__(self):
    if self.kind not in PRIMITIVES and self.kind not in meshes.GENERATORS:
      raise ValueError(f"Shape.kind must be one of {PRIMITIVES + tuple(meshes.GENERATORS)}, "
                       f"got {self.kind!r}")

  @property
  def is_mesh(self):
    return self.kind in meshes.GENERATORS

  def to_world(self):
    """[4, 4] float64 local -> world transform: translate @ rotate @ scale."""
    axis = np.asarray(self.rotation[:3], np.float64)
    axis = axis / np.linalg.norm(axis)
    angle = math.radians(self.rotation[3])
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    rot = np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)  # Rodrigues
    m = np.eye(4)
    m[:3, :3] = rot @ np.diag(np.asarray(self.scale, np.float64))
    m[:3, 3] = self.position
    return m

  def mesh(self):
    """The procedural mesh in world coordinates (`meshes.Mesh`); only for mesh kinds."""
    if not self.is_mesh:
      raise ValueError(f"shape {self.name!r} is a primitive ({self.kind}), not a mesh")
    return meshes.GENERATORS[self.kind](**dict(self.params)).transformed(self.to_world())

  def extreme_points(self):
    """[P, 3] world points whose convex hull contains the shape (for bounding checks)."""
    if self.is_mesh:
      return self.mesh().vertices.astype(np.float64)
    m = self.to_world()
    if self.kind == "sphere":  # the ellipsoid's extent along each world axis, both ways
      half = np.sqrt(np.sum(m[:3, :3] ** 2, axis=1))
      pts = np.concatenate([np.diag(half), -np.diag(half)])
      return m[:3, 3] + pts
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1)
                        for z in ((-1, 1) if self.kind == "cube" else (0,))], np.float64)
    return corners @ m[:3, :3].T + m[:3, 3]


@dataclasses.dataclass(frozen=True)
class Lighting:
  """Fixed illumination of ordinary captures: a grey sky plus a sun.

  Attributes:
    ambient: radiance of a constant environment (linear, grey).
    sun_direction: [3] direction *towards* the sun (normalised when used).
    sun_irradiance: irradiance of the directional light on a surface facing it.
  """

  ambient: float = 0.5
  sun_direction: tuple = (0.4, -0.5, 1.0)
  sun_irradiance: float = 2.2


@dataclasses.dataclass(frozen=True)
class Scene:
  """A procedural scene and its camera geometry.

  Attributes:
    name: short identifier (cache folder name).
    shapes: tuple of `Shape`.
    lighting: `Lighting` of ordinary captures (`capture`); SH captures replace it.
    center: [3] bounding-sphere centre; cameras look at it.
    radius: bounding-sphere radius (world units): every shape lies inside.
    camera_distance: radius of the camera sphere.
    fov_x: horizontal field of view of the helper cameras (radians).
    polar_range: (min, max) polar angle of candidate / test cameras, radians from +z
      (the authors clamp v = polar / pi to [0.01, 0.46]: the upper hemisphere).
    max_depth: Mitsuba path length (2 = direct light only; 4 = two indirect bounces).
    description: one line for humans.
    version: bump to invalidate cached captures after a change the fingerprint cannot see.
  """

  name: str
  shapes: tuple
  lighting: Lighting = Lighting()
  center: tuple = (0.0, 0.0, 0.0)
  radius: float = 1.0
  camera_distance: float = 3.0
  fov_x: float = math.radians(40.0)
  polar_range: tuple = (0.01 * math.pi, 0.46 * math.pi)
  max_depth: int = 4
  description: str = ""
  version: int = 1

  up = (0.0, 0.0, 1.0)  # class constant: the camera parameterisation assumes +z

  def __post_init__(self):
    names = [s.name for s in self.shapes]
    if len(set(names)) != len(names):
      raise ValueError(f"scene {self.name!r}: shape names must be unique, got {names}")
    lo, hi = self.polar_range
    if not 0.0 <= lo < hi <= math.pi:
      raise ValueError(f"polar_range must satisfy 0 <= min < max <= pi, got {self.polar_range}")

  def fingerprint(self):
    """Hex digest of everything that determines a capture's pixels (cache key part)."""
    payload = {"scene": dataclasses.asdict(self), "mesh_version": meshes.MESH_VERSION}
    text = json.dumps(payload, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()

  def bounding_error(self):
    """How far (world units) the farthest shape point lies outside the bounding sphere (<= 0
    when the sphere holds everything)."""
    pts = np.concatenate([s.extreme_points() for s in self.shapes])
    return float(np.max(np.linalg.norm(pts - np.asarray(self.center), axis=-1)) - self.radius)

  # ---------------------------------------------------------------- cameras

  def camera_at(self, azimuth, polar, width, height, *, distance=None):
    """Cameras on the sphere around `center`, looking at it with up = +z.

    Args:
      azimuth: [...] radians from +x towards +y.
      polar: [...] radians from +z.
      width, height: image size in pixels.
      distance: sphere radius (default `camera_distance`).

    Returns:
      a `Camera` batched like the broadcast of azimuth and polar.
    """
    d = self.camera_distance if distance is None else distance
    azimuth, polar = np.broadcast_arrays(np.asarray(azimuth, np.float64),
                                         np.asarray(polar, np.float64))
    direction = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                          np.cos(polar)], axis=-1)
    eye = np.asarray(self.center) + d * direction
    target = np.broadcast_to(np.asarray(self.center, np.float64), eye.shape)
    return Camera.look_at(eye.astype(np.float32), target.astype(np.float32),
                          np.asarray(self.up, np.float32), self.fov_x, width, height)

  def sample_angles(self, num, seed, stream):
    """(azimuth [num], polar [num]) uniform by area over the polar band."""
    rng = np.random.default_rng([int(seed), stream])
    lo, hi = self.polar_range
    cos_polar = rng.uniform(math.cos(hi), math.cos(lo), num)
    azimuth = rng.uniform(0.0, 2.0 * math.pi, num)
    return azimuth, np.arccos(cos_polar)

  def candidate_cameras(self, width, height, num=100, seed=0):
    """The candidate pool: `num` cameras uniform by area over the upper-hemisphere band."""
    return self.camera_at(*self.sample_angles(num, seed, stream=0), width, height)

  def test_cameras(self, width, height, num=50, seed=1):
    """Held-out test cameras: drawn from a different random stream than the candidates, so
    no test pose equals a candidate pose, whatever the seeds."""
    return self.camera_at(*self.sample_angles(num, seed, stream=1), width, height)
