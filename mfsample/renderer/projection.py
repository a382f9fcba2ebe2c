"""Stage 1: EWA projection of 3D Gaussians to screen-space ellipses.

Zwicker et al. 2002 (EWA splatting), as used by 3DGS (Kerbl et al. 2023, Sec. 4):
Sigma_3d = R S S^T R^T, Sigma_2d = J W Sigma_3d W^T J^T + eps2d I, with W the world-to-camera
rotation and J the Jacobian of the perspective map at the Gaussian's centre.

The screen footprint of a Gaussian of opacity o is the ellipse {d <= r(o)}, d the
Mahalanobis distance under Sigma_2d and

  r(o) = min(radius_sigma, sqrt(2 ln(o / alpha_min)))  (Mahalanobis units),

the distance beyond which its alpha o exp(-r^2 / 2) falls below alpha_min (3DGS, gsplat).
It lies in the disc of radius r(o) sqrt(lambda_max) pixels (lambda_max the largest
eigenvalue of Sigma_2d: `Projected.radii`) and, tighter, in the axis-aligned box of
half-widths r(o) sqrt(Sigma_2d[0, 0]) and r(o) sqrt(Sigma_2d[1, 1]) (`Projected.extents`;
the extremes of x and y over the ellipse), which decides the tiles it is listed in, as in
gsplat.
"""

from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp

from mfsample import numerics
from mfsample.renderer.precision import MATMUL

# 3DGS evaluates the Jacobian at the centre clamped to 1.3x the half field of view, so that
# Gaussians far off screen do not get exploding screen-space footprints.
_FRUSTUM_MARGIN = 1.3


class Projected(NamedTuple):
  """Screen-space Gaussians. N is the number of input Gaussians."""

  means2d: chex.Array  # [N, 2] pixel coordinates (u, v)
  conics: chex.Array  # [N, 3] inverse 2D covariance (a, b, c): [[a, b], [b, c]]
  depths: chex.Array  # [N] camera-space z
  radii: chex.Array  # [N] screen radius in pixels of the footprint (no gradient), 0 if culled
  valid: chex.Array  # [N] bool: in front of the near plane, live, on screen
  # [N, 2] half-widths in pixels (x, y) of the footprint's bounding box, <= radii (no
  # gradient), 0 if culled: the tile lists use it.
  extents: chex.Array


def quat_to_rotmat(quats):
  """[..., 4] (w, x, y, z), any norm -> [..., 3, 3]. The zero quaternion maps to identity."""
  q = numerics.safe_normalize(quats, fallback=jnp.array([1.0, 0.0, 0.0, 0.0], quats.dtype))
  w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
  rows = [
      [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
      [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
      [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
  ]
  return jnp.stack([jnp.stack(r, axis=-1) for r in rows], axis=-2)


def covariance_3d(scales, quats):
  """[N, 3] scales, [N, 4] quats -> [N, 3, 3] world covariance R S S^T R^T."""
  m = quat_to_rotmat(quats) * scales[..., None, :]
  return jnp.matmul(m, jnp.swapaxes(m, -1, -2), precision=MATMUL)


def footprint_sigma(opacities, settings):
  """r(o) = min(radius_sigma, sqrt(2 ln(o / alpha_min))): [N] -> [N] Mahalanobis radii.

  Where a Gaussian's alpha o exp(-d^2 / 2) reaches alpha_min, capped at `radius_sigma`. A
  discrete quantity (it decides which tiles list the Gaussian): no gradient. Opacities at
  or below alpha_min give 0; those Gaussians are culled anyway.
  """
  cap = settings.radius_sigma ** 2
  if settings.alpha_min <= 0.0:  # no alpha cut: the cap alone
    return jnp.full_like(opacities, settings.radius_sigma)
  o = jax.lax.stop_gradient(opacities)
  above = o > settings.alpha_min
  log_ratio = jnp.log(jnp.where(above, o, 1.0) / settings.alpha_min)
  return jnp.sqrt(jnp.where(above, jnp.minimum(cap, 2.0 * log_ratio), 0.0))


def project_gaussians(means, scales, quats, opacities, mask, camera, settings):
  """Projects Gaussians into `camera` (EWA with the perspective Jacobian).

  Args:
    means: [N, 3] world centres.
    scales: [N, 3] standard deviations (> 0).
    quats: [N, 4] rotations (w, x, y, z).
    opacities: [N] in [0, 1]; Gaussians below `alpha_min` can never contribute and are culled.
    mask: [N] bool or None; False culls.
    camera: an unbatched `Camera`.
    settings: `RenderSettings`.

  Returns:
    `Projected`. Culled Gaussians have valid = False and radius 0, and finite (meaningless)
    values elsewhere, so gradients through them are zero, never NaN.
  """
  dtype = means.dtype
  rot = camera.rotation.astype(dtype)
  p_cam = jnp.matmul(means, rot.T, precision=MATMUL) + camera.translation.astype(dtype)
  x, y, z = p_cam[:, 0], p_cam[:, 1], p_cam[:, 2]
  in_front = z > settings.near_plane
  z_safe = jnp.where(in_front, z, 1.0)  # double-where: culled rows never divide by ~0

  fx, fy, cx, cy = (camera.fx.astype(dtype), camera.fy.astype(dtype),
                    camera.cx.astype(dtype), camera.cy.astype(dtype))
  width, height = camera.width, camera.height
  u = fx * x / z_safe + cx
  v = fy * y / z_safe + cy

  # Jacobian of (x, y, z) -> (fx x / z, fy y / z) at the clamped centre.
  lim_x_pos = ((width - cx) / fx) + (_FRUSTUM_MARGIN - 1.0) * 0.5 * width / fx
  lim_x_neg = (cx / fx) + (_FRUSTUM_MARGIN - 1.0) * 0.5 * width / fx
  lim_y_pos = ((height - cy) / fy) + (_FRUSTUM_MARGIN - 1.0) * 0.5 * height / fy
  lim_y_neg = (cy / fy) + (_FRUSTUM_MARGIN - 1.0) * 0.5 * height / fy
  tx = z_safe * jnp.clip(x / z_safe, -lim_x_neg, lim_x_pos)
  ty = z_safe * jnp.clip(y / z_safe, -lim_y_neg, lim_y_pos)
  zero = jnp.zeros_like(z_safe)
  jac = jnp.stack([
      jnp.stack([fx / z_safe, zero, -fx * tx / (z_safe * z_safe)], axis=-1),
      jnp.stack([zero, fy / z_safe, -fy * ty / (z_safe * z_safe)], axis=-1),
  ], axis=-2)  # [N, 2, 3]

  cov_world = covariance_3d(scales, quats)
  jw = jnp.matmul(jac, rot, precision=MATMUL)  # [N, 2, 3]
  cov2d = jnp.matmul(jnp.matmul(jw, cov_world, precision=MATMUL), jnp.swapaxes(jw, -1, -2),
                     precision=MATMUL)
  a = cov2d[:, 0, 0] + settings.eps2d
  b = cov2d[:, 0, 1]
  c = cov2d[:, 1, 1] + settings.eps2d
  det = a * c - b * b
  # With eps2d > 0 the determinant is >= eps2d^2 for any PSD input; the guard only matters
  # for eps2d = 0 or non-finite inputs.
  det_ok = jnp.isfinite(det) & (det > 1e-12)
  det_safe = jnp.where(det_ok, det, 1.0)
  conics = jnp.stack([c, -b, a], axis=-1) / det_safe[:, None]

  # Footprint radius r(o) sqrt(lambda_max); a discrete quantity, no gradient.
  a_s, c_s, det_s = jax.lax.stop_gradient((a, c, det_safe))
  mid = 0.5 * (a_s + c_s)
  lambda_max = mid + jnp.sqrt(jnp.maximum(mid * mid - det_s, 0.0))
  sigma = footprint_sigma(opacities, settings)
  radii = sigma * jnp.sqrt(jnp.maximum(lambda_max, 0.0))
  # The box around the ellipse x^T Sigma^-1 x <= r^2: |x| <= r sqrt(a), |y| <= r sqrt(c).
  # min(., radii): the same in exact arithmetic (a, c <= lambda_max), never above in float.
  extents = jnp.minimum(sigma[:, None] * jnp.sqrt(jnp.maximum(jnp.stack([a_s, c_s], -1), 0.0)),
                        radii[:, None])
  u_s, v_s = jax.lax.stop_gradient((u, v))
  on_screen = ((u_s + radii > 0) & (u_s - radii < width)
               & (v_s + radii > 0) & (v_s - radii < height))

  valid = in_front & det_ok & on_screen & jnp.isfinite(radii)
  valid = valid & (opacities >= settings.alpha_min) & jnp.all(jnp.isfinite(means), axis=-1)
  if mask is not None:
    valid = valid & mask
  means2d = jnp.where(valid[:, None], jnp.stack([u, v], axis=-1), 0.0)
  conics = jnp.where(valid[:, None], conics, 0.0)
  radii = jnp.where(valid, radii, 0.0)
  extents = jnp.where(valid[:, None], extents, 0.0)
  depths = jnp.where(valid, z, 0.0)
  return Projected(means2d, conics, depths, radii, valid, extents)


def view_directions(means, camera):
  """[N, 3] unit directions from the camera centre to each mean (zero at the centre)."""
  return numerics.safe_normalize(means - camera.center.astype(means.dtype))
