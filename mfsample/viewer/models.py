"""The models a job leaves in its workdir, as the viewer draws and renders them.

A model is read from any `.npz` written by `mfsample.train.checkpoint.save_checkpoint`: a
training checkpoint (a `TrainState`, leaves under `.model.`), a light-planning checkpoint
(the same with transfer matrices in place of SH colour) or a round of camera planning
(`mfsample.planning.rounds`, the `Model` itself). No template state is needed: the arrays
give the groups and the capacity, the file's metadata the sampler spec that made them
(`SamplerSpec.to_dict`), so the viewer needs no training config.
"""

import functools
import re

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import view_uncertainty as unc
from mfsample.mean_render import render_mean
from mfsample.model import Model, Params, mean_gaussians
from mfsample.renderer import sh as sh_lib
from mfsample.renderer.budget import render_with_budget
from mfsample.renderer.projection import covariance_3d
from mfsample.renderer.settings import RenderSettings
from mfsample.samplers import SamplerSpec, sample_z
from mfsample.train import checkpoint as ckpt

# Leaf names of a saved Model, alone or inside a TrainState (`jax.tree_util.keystr` paths).
_LEAF = re.compile(r"^(?:\.model)?\.(?:params\.(mean|b_hat)|(signs))\['(\w+)'\]$")
_FLAT = re.compile(r"^(?:\.model)?\.(mask|sh_degree)$")


class ModelFileError(ValueError):
  """A file that holds no readable model (the message names it)."""


def read_model(path) -> Model:
  """The `Model` saved in the `.npz` at `path`.

  Args:
    path: a checkpoint or round file (module docstring).

  Raises:
    mfsample.train.checkpoint.CorruptCheckpointError: the file cannot be read (cut short,
      overwritten): the viewer then shows the checkpoint before it, as a job resumes from it.
    ModelFileError: the file is readable but holds no model, or does not record its sampler.
  """
  arrays, meta = ckpt.read_arrays(path)
  groups = {"mean": {}, "b_hat": {}, "signs": {}}
  flat = {}
  for name, value in arrays.items():
    if m := _LEAF.match(name):
      groups[m.group(1) or m.group(2)][m.group(3)] = value
    elif m := _FLAT.match(name):
      flat[m.group(1)] = value
  if not groups["mean"] or "mask" not in flat:
    raise ModelFileError(f"{path} holds no model (no mean parameters and mask)")
  model_record = meta.get("model")
  record = meta.get("sampler") or (model_record.get("sampler") if isinstance(
      model_record, dict) else None)
  try:
    spec = SamplerSpec.from_dict(record)
  except (ValueError, TypeError, AttributeError) as e:
    raise ModelFileError(f"{path} does not record the sampler that made its model ({e}): "
                         "it was written by an older mfsample; rerun the job") from e
  if not set(groups["b_hat"]) <= set(spec.groups):
    raise ModelFileError(f"{path}: its arrays hold B_hat of {sorted(groups['b_hat'])}, its "
                         f"sampler record names the groups {list(spec.groups)}")
  capacity = np.shape(flat["mask"])[:1]
  wrong = sorted(f"{kind} {g} {np.shape(v)}" for kind in ("mean", "b_hat")
                 for g, v in groups[kind].items() if np.shape(v)[:1] != capacity)
  if len(capacity) != 1 or wrong:
    raise ModelFileError(f"{path}: its arrays do not hold one model (mask "
                         f"{np.shape(flat['mask'])}; {', '.join(wrong) or 'no Gaussians'})")
  return Model(params=Params(mean=groups["mean"], b_hat=groups["b_hat"]),
               signs=groups["signs"], mask=flat["mask"].astype(bool),
               sh_degree=np.asarray(flat.get("sh_degree", 0)), spec=spec)


def is_relightable(model):
  return "transfer_dc" in model.params.mean


def live(model):
  """[C] bool numpy mask of the live Gaussians."""
  return np.asarray(model.mask, bool)


def splat_colours(model, eye, light=None):
  """[N_live, 3] display colours of the live Gaussians seen from the point `eye` [3].

  SH colour: max(sum_k sh_k Y_k(d) + 0.5, 0) as the renderer shades it; a relightable
  model: its radiance under the SH light `light` [n] (the uniform light when None). Clipped to
  [0, 1] for display.
  """
  keep = live(model)
  mean = {g: np.asarray(v)[keep] for g, v in model.params.mean.items()}
  dirs = mean["means"] - np.asarray(eye, np.float32)
  dirs /= np.maximum(np.linalg.norm(dirs, axis=-1, keepdims=True), 1e-12)
  if is_relightable(model):
    from mfsample.lighting import field
    from mfsample.lighting.lights import uniform_light

    n = mean["transfer_dc"].shape[2]
    xi = uniform_light(n) if light is None else np.asarray(light)
    rgb = np.asarray(field.radiance(mean, jnp.asarray(xi, jnp.float32), jnp.asarray(dirs)))
  else:
    g = mean_gaussians(model)
    rgb = np.asarray(sh_lib.sh_to_color(jnp.asarray(np.asarray(g.sh)[keep]), jnp.asarray(dirs)))
  return np.clip(rgb, 0.0, 1.0)


def splats(model, eye, light=None):
  """(centres [N, 3], covariances [N, 3, 3], rgbs [N, 3], opacities [N, 1]) of the live
  Gaussians of the mean model: what a splat scene node takes."""
  keep = live(model)
  g = activate_geometry(model)
  cov = covariance_3d(g.scales, g.quats)  # the renderer's own: R diag(s^2) R^T
  return (np.asarray(g.means)[keep].astype(np.float32), np.asarray(cov)[keep].astype(np.float32),
          splat_colours(model, eye, light).astype(np.float32),
          np.asarray(g.opacities)[keep, None].astype(np.float32))


def activate_geometry(model):
  """The mean model's `Gaussians` (SH colour or a relightable model's geometry alone)."""
  if is_relightable(model):
    from mfsample.lighting import field
    return field.geometry(model.params.mean, model.mask)
  return mean_gaussians(model)


# ------------------------------------------------------------------ renders of one camera


@functools.partial(jax.jit, static_argnames=("settings",))
def _relit_mean_render(model, camera, xi, *, settings):
  from mfsample.lighting import field
  return field.render_relit(model.params.mean, model.mask, xi, camera, settings=settings)


# The first render's budget: small, grown where a render needs more.
START = RenderSettings(max_intersections=1 << 12)


def render_image(model, camera, background, light=None, settings=START):
  """(mean render [H, W, 3] in [0, 1], the settings that sufficed) of the step's model seen
  by `camera`: SH colour over `background`, or a relightable model under the SH light
  `light` [n] (the budget grown where it overflows, never a truncated image)."""
  if is_relightable(model):
    out, settings = render_with_budget(_relit_mean_render, settings, model, camera,
                                       jnp.asarray(light, jnp.float32))
  else:
    out, settings = render_with_budget(render_mean, settings, model, camera,
                                       jnp.asarray(background, jnp.float32))
  return np.clip(np.asarray(out.rgb), 0, 1), settings


def render_u(model, camera, z, background, light=None, settings=START):
  """(U map [H, W], U, the settings that sufficed) of `camera`: the per-pixel map of Eq. 10
  and its sum U, with the samples `z` [M, ...]; for a relightable model U(xi) under the
  light `light` [n]. A deterministic model, or M < 2, gives zeros."""
  if z.shape[0] < 2 or not model.spec.stochastic:
    return np.zeros((camera.height, camera.width), np.float32), 0.0, settings
  if is_relightable(model):
    from mfsample.lighting.uncertainty import light_pixel_map

    (pmap, _, _), settings = render_with_budget(
        light_pixel_map, settings, model, camera, z, jnp.asarray(light, jnp.float32),
        stats_of=lambda out: out[2])
    return np.asarray(pmap), float(np.sum(pmap)), settings
  u, settings = render_with_budget(unc.uncertainty, settings, model, camera, z,
                                   background=jnp.asarray(background, jnp.float32))
  return np.asarray(u.pixel_map), float(u.value), settings


def samples(model, num, seed):
  """[M, ...] z for U maps: the job's own choice (`mfsample.samplers.sample_z`)."""
  return sample_z(model, int(num), seed=int(seed))
