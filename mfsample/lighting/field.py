"""The relightable stochastic field: per-Gaussian transfer matrices in place of SH colour.

Under a distant white SH light xi in R^n (the environment L(w) = sum_b xi_b Y_b(w), one vector
shared by the colour channels), Gaussian i emits towards a camera the linear radiance

  r_i,c(d) = sum_a Y_a(d) sum_b T_i[a, b, c] xi_b,     a < m, b < n, c < 3     (paper Sec. 5.2)

with T_i its transfer matrix (m outgoing x n light coefficients x 3 channels) and d the unit
direction from the camera centre to the Gaussian (the renderer's view direction, as for SH
colour). m = 1 is a diffuse scene (no view dependence); n = 9 or 16 light coefficients
(bands 0-2 or 0-3). There is no offset and no clamp: r is linear in xi, so every rendered
sample is linear in xi (what makes U(xi) a quadratic form, `mfsample.lighting.uncertainty`).
Clamp only for display and metrics.

The model is a `mfsample.model.Model` whose groups are the geometry of 3DGS (`means`,
`log_scales`, `quats`, `opacity_logits`) and T, split like SH colour into its outgoing DC row
`transfer_dc` [C, 1, n, 3] and its other rows `transfer_rest` [C, m - 1, n, 3] (only when
m > 1), so that each has its own learning rate and B_hat bound. There are no SH colour
groups. Capacity, mask, B_hat = relu(raw) * sign, the samplers (`mfsample.samplers.perturb`
works on any groups) and densification are the colour model's; only the activation differs:
`relit_gaussians` here instead of `mfsample.model.activate`.
"""

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks, samplers
from mfsample.gaussians import Gaussians
from mfsample.lighting import lights as lights_lib
from mfsample.model import (
    LOG_SCALE_RANGE,
    Model,
    Params,
    check_init_scales,
    check_initial,
    host_rng,
    init_b_hat,
    knn_scale,
    padding_values,
)
from mfsample.renderer import render
from mfsample.renderer import sh as sh_lib
from mfsample.renderer.projection import view_directions
from mfsample.renderer.settings import RenderSettings

GEOMETRY_GROUPS = ("means", "log_scales", "quats", "opacity_logits")
# Numbers of SH coefficients of bands 0..l, l = 0..3 (the renderer's SH basis).
COEFFICIENT_COUNTS = (1, 4, 9, 16)


def check_coefficients(out_coeffs, light_coeffs):
  """Raises ValueError unless m and n are SH coefficient counts (1, 4, 9 or 16)."""
  for name, value in (("out_coeffs (m)", out_coeffs), ("light_coeffs (n)", light_coeffs)):
    if isinstance(value, bool) or value not in COEFFICIENT_COUNTS:
      raise ValueError(f"{name} must be one of {COEFFICIENT_COUNTS} (SH bands 0..l), "
                       f"got {value!r}")


def group_shapes(out_coeffs, light_coeffs):
  """{group: per-Gaussian trailing shape} of a relightable model with m and n coefficients."""
  check_coefficients(out_coeffs, light_coeffs)
  shapes = {"means": (3,), "log_scales": (3,), "quats": (4,), "opacity_logits": (),
            "transfer_dc": (1, light_coeffs, 3)}
  if out_coeffs > 1:
    shapes["transfer_rest"] = (out_coeffs - 1, light_coeffs, 3)
  return shapes


def is_relightable(model):
  """Whether `model` holds transfer matrices (and no SH colour)."""
  return "transfer_dc" in model.params.mean


def coefficient_counts(model):
  """(m, n) of a relightable model."""
  if not is_relightable(model):
    raise ValueError("not a relightable model: it has no transfer_dc group (SH colour "
                     "models are lit by `mfsample.model.activate`)")
  dc = model.params.mean["transfer_dc"]
  rest = model.params.mean.get("transfer_rest")
  return 1 + (0 if rest is None else rest.shape[1]), dc.shape[2]


# ------------------------------------------------------------------------- activation


def transfer_matrix(raw):
  """[C, m, n, 3] T from the raw groups (a sample or the mean)."""
  t = raw["transfer_dc"]
  if "transfer_rest" in raw:
    t = jnp.concatenate([t, raw["transfer_rest"]], axis=1)
  return t


def geometry(raw, mask):
  """`Gaussians` of the geometry groups (the colour model's constraints: scale = exp(clip(
  log_scale)), opacity = sigmoid(logit), quaternions unnormalised). Their `sh` is a zero
  placeholder [C, 1, 3]: relit renders pass the radiance as `features`."""
  means = raw["means"]
  return Gaussians(
      means=means,
      scales=jnp.exp(jnp.clip(raw["log_scales"], *LOG_SCALE_RANGE)),
      quats=raw["quats"],
      opacities=jax.nn.sigmoid(raw["opacity_logits"]),
      sh=jnp.zeros((means.shape[0], 1, 3), means.dtype),
      mask=mask,
  )


def basis_radiance(raw, dirs):
  """[C, n, 3] radiance of every Gaussian under each SH basis light e_b alone.

  sum_a Y_a(d) T[a, b, c]; the radiance under xi is sum_b xi_b of these (linearity).

  Args:
    raw: raw groups with `transfer_dc` (and `transfer_rest`).
    dirs: [C, 3] unit view directions.
  """
  t = transfer_matrix(raw)
  degree = math.isqrt(t.shape[1]) - 1
  y = sh_lib.sh_basis(dirs.astype(t.dtype), degree)  # [C, m]
  return jnp.einsum("ca,cabk->cbk", y, t)


def radiance(raw, xi, dirs):
  """[C, 3] linear radiance r(d) = sum_a Y_a(d) sum_b T[a, b, c] xi_b (module docstring).

  Args:
    raw: raw groups with `transfer_dc` (and `transfer_rest`).
    xi: [n] white SH light.
    dirs: [C, 3] unit view directions.
  """
  t = transfer_matrix(raw)
  if np.shape(xi) != (t.shape[2],):
    raise ValueError(f"xi must be one SH light of {t.shape[2]} coefficients (shape "
                     f"[{t.shape[2]}]), got shape {list(np.shape(xi))}")
  if np.shape(dirs) != (t.shape[0], 3):
    raise ValueError(f"dirs must have shape [C={t.shape[0]}, 3], got {list(np.shape(dirs))}")
  degree = math.isqrt(t.shape[1]) - 1
  y = sh_lib.sh_basis(dirs.astype(t.dtype), degree)
  return jnp.einsum("ca,cabk,b->ck", y, t, jnp.asarray(xi, t.dtype))


def relit_gaussians(raw, mask, xi, camera):
  """(`Gaussians`, [C, 3] radiance features) of raw parameters lit by xi, seen by `camera`."""
  g = geometry(raw, mask)
  return g, radiance(raw, xi, view_directions(g.means, camera))


def render_relit(raw, mask, xi, camera, *, settings: RenderSettings, screen_offset=None):
  """Linear radiance image [H, W, 3] (in `.rgb`) of raw parameters under the light xi.

  The background is black (radiance 0), as in the oracle's captures; nothing is clamped. A
  concrete non-finite `xi` raises ValueError; a traced one gives a NaN image (its radiance
  would be culled Gaussian by Gaussian, leaving a black image that looks valid).
  """
  if not arg_checks.is_traced(xi):
    xi = lights_lib.check_light(xi, raw["transfer_dc"].shape[2])
  g, features = relit_gaussians(raw, mask, xi, camera)
  out = render(g, camera, settings=settings, features=features, screen_offset=screen_offset)
  return out._replace(rgb=arg_checks.nan_unless(arg_checks.all_finite(jnp.asarray(xi)),
                                                out.rgb))


@dataclasses.dataclass(frozen=True)
class RelightableField:
  """The relightable field as the training step's `Field` (`mfsample.train.step`).

  Training data: (images [L, V, H, W, 3] of L light slots and V views, lights [L, n],
  `Camera` [V]); a step's index: (light slot, view), int32 each. A sample theta(z) is
  rendered under the slot's light (`render_relit`: linear radiance, black background). No
  per-step schedule (no SH colour).
  """

  out_coeffs: int  # m
  light_coeffs: int  # n

  def prepare(self, model, step, cfg):
    del step, cfg
    return model

  def target(self, data, index):
    images, lights, cameras = data
    light, view = index
    return images[light, view], cameras[view], lights[light]

  def render(self, model, z, camera, light, cfg, screen_offset):
    return render_relit(samplers.perturb(model, z), model.mask, light, camera,
                        settings=cfg.settings, screen_offset=screen_offset)


def render_basis(raw, mask, camera, *, settings: RenderSettings):
  """(images [H, W, n, 3] under each basis light e_b, `RenderOutput`) in one render.

  The n x 3 radiance features are composited together (compositing is linear in them):
  the image under xi is sum_b xi_b images[..., b, :], exactly, for these samples.
  """
  g = geometry(raw, mask)
  feats = basis_radiance(raw, view_directions(g.means, camera))
  n = feats.shape[1]
  out = render(g, camera, settings=settings, features=feats.reshape(feats.shape[0], n * 3))
  return out.rgb.reshape(out.rgb.shape[:2] + (n, 3)), out


# ------------------------------------------------------------------------- construction


def init_relightable(key, points, *, spec, out_coeffs, light_coeffs, init_scales,
                     capacity=None, init_opacity=0.1):
  """A relightable model whose mean Gaussians sit at `points`, with T = 0 (authors' code).

  Geometry as `mfsample.model.init_model` (3DGS: isotropic scales from the 3 nearest
  neighbours, identity rotations, opacity `init_opacity`); B_hat entries of the stochastic
  groups of `spec` ~ init_scale * U[0, 1] with random signs (`mfsample.model.init_b_hat`).

  Args:
    key: PRNG key (B_hat entries and signs).
    points: [N, 3] initial centres (host array), N >= 1.
    spec: `SamplerSpec` (groups among `GEOMETRY_GROUPS` and the transfer groups).
    out_coeffs: m, outgoing SH coefficients (1: diffuse).
    light_coeffs: n, light SH coefficients.
    init_scales: {group: float} see `init_b_hat`.
    capacity: C >= N (default `mfsample.model.capacity_bucket(N)`).
    init_opacity: initial opacity in (0, 1).

  Returns:
    `Model` with the first N rows live (float32; `sh_degree` is unused and 0).
  """
  points, capacity = check_initial(points, capacity, init_opacity)
  shapes = group_shapes(out_coeffs, light_coeffs)
  unknown = set(spec.groups) - set(shapes)
  if unknown:
    raise ValueError(f"stochastic groups {sorted(unknown)} are not groups of a relightable "
                     f"model with m={out_coeffs}: {tuple(shapes)}")
  check_init_scales(init_scales, spec, shapes)
  n = len(points)
  quats = np.zeros((n, 4))
  quats[:, 0] = 1.0
  mean = {"means": points,
          "log_scales": np.repeat(np.log(knn_scale(points))[:, None], 3, 1),
          "quats": quats,
          "opacity_logits": np.full((n,), np.log(init_opacity / (1 - init_opacity)))}
  for g in ("transfer_dc", "transfer_rest"):
    if g in shapes:
      mean[g] = np.zeros((n,) + shapes[g])
  pad = padding_values(shapes, capacity - n)
  mean = {g: jnp.asarray(np.concatenate([v.astype(np.float32), pad[g]], axis=0))
          for g, v in mean.items()}
  b_hat, signs = init_b_hat(host_rng(key), n, shapes, spec, init_scales)

  def padded(x):
    return jnp.asarray(np.concatenate([x, np.zeros((capacity - n,) + x.shape[1:], x.dtype)]))

  return Model(Params(mean, {g: padded(v) for g, v in b_hat.items()}),
               {g: padded(v) for g, v in signs.items()}, jnp.asarray(np.arange(capacity) < n),
               jnp.asarray(0, jnp.int32), spec)
