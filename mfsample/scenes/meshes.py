"""Procedural triangle meshes in numpy (no Mitsuba needed): solids of revolution and a torus.

Every mesh is a closed, consistently wound solid: triangle (a, b, c) has its geometric normal
(b - a) x (c - a) pointing out of the solid, and the vertex (shading) normals agree with it.
Mitsuba's BSDFs are one-sided, so a flipped triangle would render black.

Solids of revolution are described by a profile in the (r, z) half-plane: a list of
polylines, traversed counter-clockwise around the solid's cross-section (with r to the right
and z up, the solid lies on the left). Each polyline is smooth; consecutive polylines meet at
a crease (their vertices are not shared), which keeps rims and edges sharp.
"""

from typing import NamedTuple

import numpy as np

# Bump when a generator's output changes: it is part of every capture's cache key.
MESH_VERSION = 1


class Mesh(NamedTuple):
  """A triangle mesh.

  Attributes:
    vertices: [V, 3] float32 positions.
    normals: [V, 3] float32 unit shading normals.
    uvs: [V, 2] float32 texture coordinates.
    faces: [F, 3] uint32 vertex indices, wound so that normals point outwards.
  """

  vertices: np.ndarray
  normals: np.ndarray
  uvs: np.ndarray
  faces: np.ndarray

  def transformed(self, matrix):
    """The mesh under a [4, 4] affine transform (normals by the inverse transpose)."""
    m = np.asarray(matrix, np.float64)
    verts = self.vertices @ m[:3, :3].T + m[:3, 3]
    normals = self.normals @ np.linalg.inv(m[:3, :3])
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    faces = self.faces
    if np.linalg.det(m[:3, :3]) < 0:  # a mirror flips the winding
      faces = faces[:, ::-1]
    return Mesh(verts.astype(np.float32), normals.astype(np.float32), self.uvs,
                np.ascontiguousarray(faces))


def revolve(profile, segments=48, uv="cylindrical"):
  """A solid of revolution about the z axis.

  Args:
    profile: list of polylines, each [P_i, 2] points (r >= 0, z); see the module docstring
      for the orientation. A polyline whose last point equals its first is closed (smooth
      all the way round, e.g. a torus' circle).
    segments: number of angular steps.
    uv: "cylindrical" (u = angle / 2 pi, v = arc length along the whole profile, in [0, 1])
      or "planar" (u, v = x, y mapped from [-r_max, r_max] to [0, 1]; for flat tops).

  Returns:
    `Mesh`.
  """
  polylines = [np.asarray(p, np.float64) for p in profile]
  lengths = [np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=-1))])
             for p in polylines]
  total = sum(length[-1] for length in lengths)
  r_max = max(p[:, 0].max() for p in polylines)
  phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)  # the seam column is duplicated for uv
  cos, sin = np.cos(phi), np.sin(phi)

  verts, normals, uvs, faces = [], [], [], []
  offset, arc_start = 0, 0.0
  for points, length in zip(polylines, lengths, strict=True):
    n2 = _profile_normals(points)
    rows = len(points)
    pos = np.stack([points[:, :1] * cos, points[:, :1] * sin,
                    np.broadcast_to(points[:, 1:], (rows, segments + 1))], axis=-1)
    nrm = np.stack([n2[:, :1] * cos, n2[:, :1] * sin,
                    np.broadcast_to(n2[:, 1:], (rows, segments + 1))], axis=-1)
    if uv == "cylindrical":
      u = np.broadcast_to(phi / (2.0 * np.pi), (rows, segments + 1))
      v = np.broadcast_to(((arc_start + length) / total)[:, None], (rows, segments + 1))
      tex = np.stack([u, v], axis=-1)
    elif uv == "planar":
      tex = 0.5 + 0.5 * pos[..., :2] / r_max
    else:
      raise ValueError(f"uv must be 'cylindrical' or 'planar', got {uv!r}")
    idx = offset + np.arange(rows * (segments + 1)).reshape(rows, segments + 1)
    a, b = idx[:-1, :-1], idx[:-1, 1:]  # (i, j), (i, j + 1)
    c, d = idx[1:, :-1], idx[1:, 1:]    # (i + 1, j), (i + 1, j + 1)
    # dP/dphi x dP/ds points out of the solid for a counter-clockwise profile.
    quads = np.stack([np.stack([a, b, c], -1), np.stack([c, b, d], -1)], axis=2)
    keep = _non_degenerate(pos.reshape(-1, 3), quads.reshape(-1, 3) - offset)
    faces.append(quads.reshape(-1, 3)[keep])
    verts.append(pos.reshape(-1, 3))
    normals.append(nrm.reshape(-1, 3))
    uvs.append(tex.reshape(-1, 2))
    offset += rows * (segments + 1)
    arc_start += length[-1]
  return Mesh(np.concatenate(verts).astype(np.float32),
              np.concatenate(normals).astype(np.float32),
              np.concatenate(uvs).astype(np.float32),
              np.concatenate(faces).astype(np.uint32))


def _profile_normals(points):
  """[P, 2] outward (r, z) normals at the polyline's points (averaged over adjacent edges)."""
  edges = np.diff(points, axis=0)
  edge_n = np.stack([edges[:, 1], -edges[:, 0]], axis=-1)  # tangent rotated clockwise
  edge_n /= np.maximum(np.linalg.norm(edge_n, axis=-1, keepdims=True), 1e-12)
  normals = np.zeros_like(points)
  normals[:-1] += edge_n
  normals[1:] += edge_n
  if np.allclose(points[0], points[-1]):  # closed: the end points are one smooth point
    normals[0] = normals[-1] = normals[0] + normals[-1]
  return normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)


def _non_degenerate(verts, tris):
  """Mask of triangles with non-zero area (quads touching the axis collapse to triangles)."""
  p = verts[tris]
  area2 = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=-1)
  return area2 > 1e-12


# ------------------------------------------------------------------ generators
# Local frame of every generator: axis along +z, resting on z = 0.


def bowl(radius=0.25, height=0.18, thickness=0.025, foot=0.35, segments=48, rings=16):
  """A round bowl: concave inside, with a flat foot (radius = `foot` x radius)."""
  theta0 = np.arcsin(foot)
  theta = np.linspace(theta0, 0.5 * np.pi, rings)
  # An ellipsoidal wall, starting at the foot's edge on z = 0 and ending at the rim.
  outer = np.stack([radius * np.sin(theta),
                    height * (np.cos(theta0) - np.cos(theta)) / np.cos(theta0)], -1)
  inner_r = radius - thickness
  t_in = np.linspace(0.5 * np.pi, 0.0, rings)
  inner = np.stack([inner_r * np.sin(t_in),
                    thickness + (height - thickness) * (1.0 - np.cos(t_in))], -1)
  profile = [
      [(0.0, 0.0), (radius * foot, 0.0)],          # foot (flat bottom)
      outer,                                       # outer wall, up to the rim
      [(radius, height), (inner_r, height)],       # flat rim
      inner,                                       # inner wall, down to the axis
  ]
  return revolve(profile, segments)


def cup(radius=0.12, height=0.24, thickness=0.015, segments=48):
  """A straight cup: open top, flat bottom inside and out."""
  r_in = radius - thickness
  profile = [
      [(0.0, 0.0), (radius, 0.0)],
      [(radius, 0.0), (radius, height)],
      [(radius, height), (r_in, height)],
      [(r_in, height), (r_in, thickness)],
      [(r_in, thickness), (0.0, thickness)],
  ]
  return revolve(profile, segments)


def can(radius=0.1, height=0.3, segments=48):
  """A closed cylinder (cylindrical uv on the side, wrapping once around)."""
  profile = [
      [(0.0, 0.0), (radius, 0.0)],
      [(radius, 0.0), (radius, height)],
      [(radius, height), (0.0, height)],
  ]
  return revolve(profile, segments)


def plate(radius=0.9, thickness=0.04, segments=64):
  """A flat round slab; planar uv, so a texture on it is undistorted from above."""
  profile = [
      [(0.0, 0.0), (radius, 0.0)],
      [(radius, 0.0), (radius, thickness)],
      [(radius, thickness), (0.0, thickness)],
  ]
  return revolve(profile, segments, uv="planar")


def torus(major=0.14, minor=0.045, segments=48, rings=24):
  """A torus around the z axis, resting on z = 0 (its centre at z = minor)."""
  t = np.linspace(-0.5 * np.pi, 1.5 * np.pi, rings + 1)  # from the bottom, counter-clockwise
  circle = np.stack([major + minor * np.cos(t), minor + minor * np.sin(t)], -1)
  circle[-1] = circle[0]
  return revolve([circle], segments)


def vase(radius=0.11, height=0.34, neck=0.45, thickness=0.012, segments=48, rings=24):
  """A vase: a bulging body narrowing to a neck (radius `neck` x radius), open at the top."""
  s = np.linspace(0.0, 1.0, rings)
  r_out = radius * (neck + (1.0 - neck) * np.sin(np.pi * s) ** 0.7)  # bulging body
  outer = np.stack([r_out, height * s], -1)
  inner = np.stack([r_out - thickness, thickness + (height - thickness) * s], -1)[::-1]
  profile = [
      [(0.0, 0.0), (r_out[0], 0.0)],
      outer,
      [(r_out[-1], height), (inner[0, 0], height)],
      inner,
      [(inner[-1, 0], thickness), (0.0, thickness)],
  ]
  return revolve(profile, segments)


GENERATORS = {
    "bowl": bowl,
    "cup": cup,
    "can": can,
    "plate": plate,
    "torus": torus,
    "vase": vase,
}


def signed_volume(mesh):
  """Volume enclosed by a closed mesh (> 0 when the winding points outwards)."""
  p = mesh.vertices.astype(np.float64)[mesh.faces]
  return float(np.einsum("fi,fi->f", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)
