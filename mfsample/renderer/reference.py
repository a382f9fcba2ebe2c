"""A brute-force dense renderer: every pixel against every Gaussian.

Written separately and as plainly as possible, as the ground truth that the tiled renderer is
tested against. It shares only the quaternion and SH helpers (tested on their own). Memory is
O(H W N): for small test scenes only.

The rasterisation rule, literally: Gaussian i contributes at pixel p iff its Mahalanobis
distance d_i(p) <= r(o_i) = min(radius_sigma, sqrt(2 ln(o_i / alpha_min))) and its alpha is
at least alpha_min (the same thing but for rounding at the boundary). Every product runs in
full float32 (`precision.py`), so that it is a reference on a GPU too.
"""

import functools

import jax.numpy as jnp

from mfsample.renderer.precision import MATMUL
from mfsample.renderer.projection import quat_to_rotmat
from mfsample.renderer.sh import sh_to_color

_mm = functools.partial(jnp.matmul, precision=MATMUL)


def render_reference(gaussians, camera, *, background=None, settings, features=None):
  """Same contract as `mfsample.render` (without stats): returns (rgb, alpha, depth)."""
  s = settings
  means, scales, quats = gaussians.means, gaussians.scales, gaussians.quats
  n = means.shape[0]
  w, h = camera.width, camera.height
  rot, trans = camera.world_to_camera[:3, :3], camera.world_to_camera[:3, 3]

  # Camera-space centres and the 3DGS perspective Jacobian (clamped to 1.3x the FOV).
  pc = _mm(means, rot.T) + trans
  x, y, z = pc[:, 0], pc[:, 1], pc[:, 2]
  alive = z > s.near_plane
  if gaussians.mask is not None:
    alive = alive & gaussians.mask
  z = jnp.where(alive, z, 1.0)
  fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
  lim_xp = (w - cx) / fx + 0.15 * w / fx
  lim_xn = cx / fx + 0.15 * w / fx
  lim_yp = (h - cy) / fy + 0.15 * h / fy
  lim_yn = cy / fy + 0.15 * h / fy
  xc = jnp.clip(x / z, -lim_xn, lim_xp) * z
  yc = jnp.clip(y / z, -lim_yn, lim_yp) * z
  jac = jnp.zeros((n, 2, 3), means.dtype)
  jac = jac.at[:, 0, 0].set(fx / z).at[:, 0, 2].set(-fx * xc / z**2)
  jac = jac.at[:, 1, 1].set(fy / z).at[:, 1, 2].set(-fy * yc / z**2)

  rmat = quat_to_rotmat(quats)
  sigma = _mm(_mm(rmat, jnp.eye(3, dtype=means.dtype) * scales[:, None, :] ** 2),
              jnp.swapaxes(rmat, 1, 2))
  cov2d = _mm(_mm(_mm(_mm(jac, rot), sigma), rot.T), jnp.swapaxes(jac, 1, 2))
  cov2d = cov2d + s.eps2d * jnp.eye(2, dtype=means.dtype)
  inv = jnp.linalg.inv(cov2d)  # [N, 2, 2]
  mean2d = jnp.stack([fx * x / z + cx, fy * y / z + cy], axis=-1)

  if features is None:
    dirs = means - camera.center
    dirs = dirs / jnp.maximum(jnp.linalg.norm(dirs, axis=-1, keepdims=True), 1e-12)
    colors = sh_to_color(gaussians.sh, dirs)
  else:
    colors = features
  if background is None:
    background = jnp.zeros((colors.shape[-1],), means.dtype)

  # Every pixel centre against every Gaussian, Gaussians sorted front to back.
  order = jnp.argsort(jnp.where(alive, z, jnp.inf), stable=True)
  jj, ii = jnp.meshgrid(jnp.arange(w), jnp.arange(h))
  pix = jnp.stack([jj, ii], axis=-1).reshape(-1, 2).astype(means.dtype) + 0.5  # [P, 2]
  d = pix[:, None, :] - mean2d[order][None, :, :]  # [P, N, 2]
  maha = jnp.einsum("pni,nij,pnj->pn", d, inv[order], d, precision=MATMUL)  # d_i(p)^2
  opacity = gaussians.opacities[order][None, :]
  alpha = jnp.minimum(s.alpha_max, opacity * jnp.exp(-0.5 * maha))
  r2 = jnp.full_like(opacity, s.radius_sigma**2)  # r(o)^2
  if s.alpha_min > 0:
    r2 = jnp.minimum(r2, 2.0 * jnp.log(jnp.maximum(opacity, 1e-30) / s.alpha_min))
  use = (alive[order][None, :] & (maha <= r2) & (alpha >= s.alpha_min)
         & (opacity >= s.alpha_min))
  alpha = jnp.where(use, alpha, 0.0)
  trans_before = jnp.cumprod(
      jnp.concatenate([jnp.ones_like(alpha[:, :1]), 1.0 - alpha[:, :-1]], axis=1), axis=1)
  # 3DGS stops at the first Gaussian that would push transmittance below the threshold.
  stop = trans_before * (1.0 - alpha) < s.transmittance_min
  stopped = jnp.cumsum(stop, axis=1) > 0
  weight = jnp.where(stopped, 0.0, alpha * trans_before)
  rgb = _mm(weight, colors[order]) + (1.0 - weight.sum(1))[:, None] * background
  depth = _mm(weight, jnp.where(alive, z, 0.0)[order])
  alpha_img = weight.sum(1)
  return (rgb.reshape(h, w, -1), alpha_img.reshape(h, w), depth.reshape(h, w))

