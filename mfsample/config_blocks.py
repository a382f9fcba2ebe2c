"""The config blocks every job shares, and their one translator each into typed settings.

A job's config file composes these blocks instead of copying them:

| block      | built by          | translated by     | into                               |
| ---------- | ----------------- | ----------------- | ---------------------------------- |
| `render`   | `render_block`    | `render_settings` | `RenderSettings` (+ `max_budget`)  |
| `sampler`  | `sampler_block`   | `sampler_spec`    | `SamplerSpec`; its training fields |
| `loss`     | `loss_block`      | `loss_settings`   | `LossSettings`                     |
| `optim`    | `optim_block`     | `optim_settings`  | `OptimSettings` (+ `sampler.lr`)   |
| `densify`  | `densify_block`   | `densify_settings`| `DensifySettings`                  |
| `model`    | `model_block`     | `init_settings`   | `InitSettings`                     |
| `data`     | `data_block`      | `data_spec`       | `DataSpec` (with `SyntheticSpec`)  |

and `train_settings` assembles a training config's `TrainSettings`. The rules of every field
are the settings objects' (`mfsample.settings_checks`): a validator calls the translator, and
an error names the config field (`config_checks.translated`). Everything below the jobs
takes the settings, never a config.

Numbers without a comment on their origin follow 3DGS (Kerbl et al. 2023); those of B_hat
follow the authors' public code, where the paper is silent.
"""

import ml_collections
from ml_collections import config_dict

from mfsample.config_checks import translated
from mfsample.data.datasets import DataSpec, SyntheticSpec
from mfsample.groups import GROUP_ORDER, GROUPS
from mfsample.renderer.settings import RenderSettings
from mfsample.samplers import DEFAULT_BOUNDS, SamplerSpec
from mfsample.train import settings as ts

# ----------------------------------------------------------------- render


def render_block(max_intersections=1 << 16):
  """The static renderer settings of a job's renders."""
  render = ml_collections.ConfigDict()
  render.max_intersections = max_intersections  # Initial budget; grown (power of 2) on overflow.
  render.max_budget = 1 << 24  # Refuse to grow beyond this (error, never truncation).
  render.tile_size = 16  # Screen tile side in pixels.
  # Chunks of 32 Gaussians per step of the compositing loop: speed only (images agree to
  # float rounding). 16 is fastest on CPU (`benchmarks/render.py --chunks_per_step`); a GPU,
  # where each step's launch latency dominates small steps, may want many more.
  render.chunks_per_step = 16
  # A Gaussian reaches min(radius_sigma, sqrt(2 ln(opacity / alpha_min))) standard
  # deviations: 3.33 lets the alpha rule of 3DGS / gsplat decide; 3.0 reproduces results
  # made with mfsample's former 3-sigma cut (docs/renderer.md).
  render.radius_sigma = 3.33
  # Compositor: "jnp" (every backend, the reference) or "pallas" (the GPU kernel; on a CPU
  # it runs interpreted, slowly). Speed only: the images agree to float rounding.
  render.compositor = "jnp"
  return render


# Render fields that change only how fast a job goes, never what it computes (beyond float
# rounding): a resumed run or a reused result may differ in them.
SPEED_ONLY_RENDER_FIELDS = ("render.chunks_per_step", "render.compositor")


def speed_only_fields(prefix=""):
  """`SPEED_ONLY_RENDER_FIELDS` of a render block found under `prefix` ("round_train")."""
  return tuple(f"{prefix}.{f}" if prefix else f for f in SPEED_ONLY_RENDER_FIELDS)


def render_settings(block, prefix="config.render"):
  """`RenderSettings` of a `render` block.

  The initial budget is rounded up to a whole number of compositing steps
  (chunk_size x chunks_per_step), so any `chunks_per_step` is valid with any start.
  """
  with translated({"RenderSettings": ""}, prefix):
    for name in ("max_intersections", "max_budget"):
      ts.sc.check_int(f"RenderSettings.{name}", block[name], minimum=1)
    if block.max_intersections > block.max_budget:
      raise ts.sc.SettingsError("RenderSettings.max_budget", block.max_budget,
                                f"an integer >= max_intersections = {block.max_intersections}")
    ts.sc.check_int("RenderSettings.chunks_per_step", block.chunks_per_step, minimum=1)
    return RenderSettings.holding(
        block.max_intersections, tile_size=block.tile_size,
        chunks_per_step=block.chunks_per_step, radius_sigma=block.radius_sigma,
        compositor=block.compositor)


# ----------------------------------------------------------------- sampler


def sampler_block(groups=GROUPS, bounds=None, lr=None):
  """The stochastic field: theta(z) = mean + B_hat z (its kind, rank and training)."""
  sampler = ml_collections.ConfigDict()
  sampler.kind = "lowrank"  # "lowrank" (paper), "block", "diagonal" or "deterministic".
  sampler.rank = 2  # k, columns of B_hat (paper default 2); also the rank of each block.
  sampler.groups = tuple(groups)  # Stochastic parameter groups (others are deterministic).
  sampler.num_samples = 1  # M, samples rendered per training step (paper: 1).
  # Steps that render samples; later steps render the mean (the volume term goes on).
  # None: every step (the paper's text). The authors' code: 3000 (the first opacity reset).
  sampler.stochastic_until = config_dict.placeholder(int)
  sampler.z = "sobol"  # lowrank z source: "sobol" (scrambled, paper) or "uniform".
  sampler.z_seed = 6174  # Scrambling seed of the Sobol sequence (authors' code: 6174).
  sampler.init_scale = 1e-3  # Raw B_hat entries start at init_scale * U[0, 1] ...
  sampler.init_extent_groups = ("means", "log_scales")  # ... times extent for these groups.
  # relu(raw) is kept in [0, bound]; the centres' in units of the scene extent. Defaults:
  # centres 1.0, log-scales 20, quaternions 2, opacity logits 20, SH DC and rest 0.5.
  sampler.bounds = ml_collections.ConfigDict(dict(bounds or {
      g: b for g, b in DEFAULT_BOUNDS.items() if g in GROUPS}))
  # Adam learning rates of raw B_hat entries; the centres' times the scene extent (constant:
  # only the mean's decays).
  sampler.lr = ml_collections.ConfigDict(dict(lr or {g: r for g, r in ts.B_HAT_LR.items()
                                                     if g in GROUPS}))
  return sampler


def sampler_spec(block, extent, shapes, prefix="config.sampler"):
  """The `SamplerSpec` of a `sampler` block for a model with parameter groups `shapes`
  ({group: shape}) and scene `extent`: the groups it holds, the centres' bound times the
  extent."""
  with translated({"SamplerSpec": "", "SamplerSpec.bounds": "bounds"}, prefix):
    # Every name known; those of groups the model does not hold (SH rest of a degree-0 model)
    # are left out.
    groups = tuple(g for g in ts.sc.check_names("SamplerSpec.groups", block.groups,
                                                GROUP_ORDER) if g in shapes)
    bounds = dict(block.bounds)
    missing = [g for g in groups if g not in bounds]
    if missing:
      raise ts.sc.SettingsError("SamplerSpec.bounds", bounds, f"a bound for each group "
                                f"(missing: {missing})")
    return SamplerSpec(kind=block.kind, rank=block.rank, groups=groups,
                       bounds=tuple((g, bounds[g] * (extent if g == "means" else 1.0))
                                    for g in groups), z=block.z)


# ----------------------------------------------------------------- loss, optimiser, densify


def loss_block(volume_weight=None, volume_stop_before_end=100):
  """Eq. 9: the photometric term and the volume term."""
  loss = ml_collections.ConfigDict()
  loss.ssim_weight = 0.2  # w in (1 - w) L1 + w (1 - SSIM).
  # lambda of the volume term on the plain sum of |B_hat|. None: 1 / (training views), as
  # in the authors' code; the paper's text says 1 (docs/training.md).
  loss.volume_weight = config_dict.placeholder(float) if volume_weight is None \
      else volume_weight
  loss.volume_every = 10  # The volume term is applied on every 10th step only (paper).
  loss.volume_stop_before_end = volume_stop_before_end  # No volume term in the last steps.
  return loss


def loss_settings(block, prefix="config.loss"):
  with translated({"LossSettings": ""}, prefix):
    return ts.LossSettings(ssim_weight=block.ssim_weight, volume_weight=block.volume_weight,
                           volume_every=block.volume_every,
                           volume_stop_before_end=block.volume_stop_before_end)


def optim_block(rates=None):
  """Adam learning rates of the mean: the centres' decay, one rate per other group."""
  optim = ml_collections.ConfigDict()
  optim.position_lr_init = 1.6e-4  # Times extent; decays exponentially ...
  optim.position_lr_final = 1.6e-6  # ... to this (times extent) ...
  optim.position_lr_max_steps = config_dict.placeholder(int)  # ... over this (None: all).
  # Log-scales 5e-3, quaternions 1e-3, opacity logits 0.05, SH DC 2.5e-3 ("feature" lr of
  # 3DGS), higher SH bands 1.25e-4 (3DGS: feature lr / 20).
  colour = {g: r for g, r in ts.MEAN_LR.items() if g in GROUPS}
  for group, rate in (rates or colour).items():
    optim[group] = rate
  return optim


_POSITION_FIELDS = ("position_lr_init", "position_lr_final", "position_lr_max_steps")


def optim_settings(optim, b_hat_lr, prefix="config"):
  """`OptimSettings` of an `optim` block and a sampler block's `lr` block."""
  names = {"OptimSettings": "optim", "OptimSettings.mean_lr": "optim",
           "OptimSettings.b_hat_lr": "sampler.lr"}
  with translated(names, prefix):
    return ts.OptimSettings(
        position_lr_init=optim.position_lr_init, position_lr_final=optim.position_lr_final,
        position_lr_max_steps=optim.get("position_lr_max_steps"),
        mean_lr={g: v for g, v in optim.items() if g not in _POSITION_FIELDS},
        b_hat_lr=dict(b_hat_lr))


def densify_block():
  """3DGS density control."""
  densify = ml_collections.ConfigDict()
  densify.start = 500  # First densification after this step ...
  densify.stop = 15_000  # ... and none from this step on ...
  densify.every = 100  # ... every this many steps.
  densify.grad_threshold = 2e-4  # Mean NDC gradient norm that triggers clone / split.
  densify.percent_dense = 0.01  # Clone if max scale <= this x extent, else split.
  densify.min_opacity = 0.005  # Prune below this opacity (3DGS; the authors' code: 0.01).
  densify.opacity_reset_every = 3000  # Opacity reset period (while densifying).
  densify.prune_big_after = 3000  # From this step on, also prune very large Gaussians:
  densify.max_world_size = 0.1  # ... larger than this x extent ...
  # ... or (if > 0) wider than this many pixels on screen. 3DGS passes 20 px, but resets the
  # radii it compares right before, so in effect it never prunes by screen size; 0 = off.
  densify.max_screen_size = 0.0
  densify.sh_degree_every = 1000  # The active SH degree rises by one this often.
  return densify


def densify_settings(block, max_gaussians, prefix="config"):
  """`DensifySettings` of a `densify` block (and the model block's `max_gaussians`)."""
  names = {"DensifySettings": "densify", "DensifySettings.max_gaussians": "model.max_gaussians"}
  fields = ("start", "stop", "every", "grad_threshold", "percent_dense", "min_opacity",
            "opacity_reset_every", "prune_big_after", "max_world_size", "max_screen_size")
  with translated(names, prefix):
    return ts.DensifySettings(max_gaussians=max_gaussians, **{f: block[f] for f in fields})


# ----------------------------------------------------------------- the model


def model_block():
  """The Gaussians a training run starts from, and their capacity."""
  model = ml_collections.ConfigDict()
  model.sh_degree = 3  # Maximum SH degree; 0 stores no SH-rest arrays at all.
  # Random initial points (no SfM). 3DGS uses 100k at 800x800 on NeRF Synthetic; a 128^2
  # image has 39x fewer pixels, and ~5k points already give several per pixel footprint.
  model.init_points = 5_000
  model.init_opacity = 0.1  # Initial opacity of every Gaussian.
  # Where the Gaussians start (mfsample.train.initial): "random" (init_points in the scene
  # box), "points" (the dataset's SfM points and colours: data.kind "colmap" or "nerfstudio")
  # or "ply" (the Gaussians of a trained 3DGS model, model.ply_path; model.sh_degree must
  # match it).
  model.init_from = "random"
  model.ply_path = ""  # init_from "ply": a 3DGS point_cloud.ply (relative: to the cwd).
  model.max_gaussians = 40_000  # Densification never exceeds this many live Gaussians.
  return model


def init_settings(block, prefix="config.model"):
  """`InitSettings` of a `model` block."""
  with translated({"InitSettings": ""}, prefix):
    return ts.InitSettings(sh_degree=block.sh_degree, init_points=block.init_points,
                           init_opacity=block.init_opacity, init_from=block.init_from,
                           ply_path=block.ply_path)


# ----------------------------------------------------------------- a training config


def train_settings(config, prefix="config"):
  """The `TrainSettings` of a training config (`mfsample.train.config.default_config()`
  layout: `sampler`, `loss`, `optim`, `densify`, `render`, `train`, `data.extent`,
  `data.background`, `model.max_gaussians`)."""
  s = config.sampler
  names = {"TrainSettings.num_steps": "train.num_steps",
           "TrainSettings.batch_size": "train.batch_size",
           "TrainSettings.log_every": "train.log_every",
           "TrainSettings.num_samples": "sampler.num_samples",
           "TrainSettings.stochastic_until": "sampler.stochastic_until",
           "TrainSettings.z_seed": "sampler.z_seed",
           "TrainSettings.b_hat_init_scale": "sampler.init_scale",
           "TrainSettings.b_hat_init_extent_groups": "sampler.init_extent_groups",
           "TrainSettings.extent": "data.extent",
           "TrainSettings.background": "data.background",
           "TrainSettings.sh_degree_every": "densify.sh_degree_every",
           "TrainSettings.max_budget": "render.max_budget"}
  render = render_settings(config.render, f"{prefix}.render")
  parts = dict(loss=loss_settings(config.loss, f"{prefix}.loss"),
               optim=optim_settings(config.optim, s.lr, prefix),
               densify=densify_settings(config.densify, config.model.max_gaussians, prefix))
  with translated(names, prefix):
    return ts.TrainSettings(
        num_steps=config.train.num_steps, batch_size=config.train.batch_size,
        num_samples=s.num_samples, stochastic_until=s.stochastic_until, z_seed=s.z_seed,
        b_hat_init_scale=s.init_scale, b_hat_init_extent_groups=tuple(s.init_extent_groups),
        extent=config.data.extent, background=tuple(config.data.background),
        sh_degree_every=config.densify.sh_degree_every, max_budget=config.render.max_budget,
        log_every=config.train.log_every, render=render, **parts)


def from_block(cls, block, prefix, **fields):
  """A settings dataclass `cls` from the config `block` whose fields have its fields' names
  (those the block lacks keep their defaults; `fields` override), errors naming the config
  field under `prefix`."""
  import dataclasses

  names = {f.name for f in dataclasses.fields(cls)}
  values = {k: (tuple(v) if isinstance(v, list) else v) for k, v in block.items()
            if k in names}
  with translated({cls.__name__: ""}, prefix):
    return cls(**{**values, **fields})


# ----------------------------------------------------------------- data

# 0.8 radians: the field of view of the orbit cameras of the training data's synthetic scene.
ORBIT_FOV_DEG = 45.83662361046586


def data_block(**fields):
  """Which views a job trains and tests on (`mfsample.data.DATA_KINDS`); `fields` override
  the defaults ("synthetic.shape" reaches into the synthetic block)."""
  data = ml_collections.ConfigDict()
  # "scene" (a built-in Mitsuba scene, captured on demand), "synthetic" (random Gaussians
  # rendered by mfsample), "blender" (NeRF Synthetic), "colmap" (a COLMAP capture), "llff"
  # or "nerfstudio" (ns-process-data's transforms.json): mfsample.data.DATA_KINDS.
  data.kind = "scene"
  # blender, colmap, llff, nerfstudio: the scene folder (relative: to the cwd).
  data.path = "data/nerf_synthetic/lego"
  # blender: integer image downscale (lego's files are 400 x 400); colmap, llff,
  # nerfstudio: read the pre-downscaled images_{downscale}/ folder (1: images/).
  data.downscale = 1
  data.test_every = 1  # blender: evaluate every n-th test view (1: all 200).
  # colmap, llff, nerfstudio: every n-th image (by name, from the first) is a test view, the
  # others train (the Mip-NeRF 360 / 3DGS split: 8).
  data.holdout_every = 8
  data.scene = "default"  # scene: the mfsample.scenes.get_scene name.
  data.width = 128  # scene, synthetic: image width in pixels.
  data.height = 128  # scene, synthetic: image height in pixels.
  data.num_train = 100  # scene, synthetic: training (candidate) cameras.
  data.num_test = 50  # scene, synthetic: held-out test cameras.
  data.camera_seed = 0  # scene, synthetic "band": seed of the training poses (test: + 1).
  data.spp = 36  # scene: Mitsuba samples per pixel of a capture (mfsample.scenes.DEFAULT_SPP).
  data.cache_dir = ""  # scene: capture cache ("": $MFSAMPLE_CACHE or ~/.cache/mfsample/captures).
  data.background = (1.0, 1.0, 1.0)  # Colour behind the scene, in the images and the models.
  data.init_bounds = (-1.3, 1.3)  # blender: the cube around the origin holding the scene.
  data.progress = True  # Progress bars of the captures.
  # A later call on a workdir whose results were computed from files that have changed
  # since (the dataset's, a .ply): "stop" (an error naming them) or "recompute" (remove the
  # results and compute them again). Read from the job's own data block; free to change.
  data.inputs_changed = "stop"
  data.synthetic = syn = ml_collections.ConfigDict()  # kind "synthetic": random Gaussians.
  # "random" (uniform in a cube, random colours), "shell" (an opaque shell) or "cloud".
  syn.shape = "random"
  syn.num_gaussians = 200  # Ground-truth Gaussians.
  syn.seed = 0  # Their seed.
  syn.sh_degree = 0  # "random": the SH degree of their colour.
  syn.radius = 0.6  # The shell's radius or the cube's half-side (scene box: + 0.2).
  # "orbit" (a spiral around the origin, test views in between) or "band" (uniform over the
  # polar band v_range, seeded by camera_seed: new poses on the same sphere).
  syn.cameras = "orbit"
  syn.distance = 3.0  # The cameras' distance from the origin.
  syn.v_range = (0.1, 0.6)  # "band": the polar band (v = polar / pi).
  syn.fov_x_deg = ORBIT_FOV_DEG  # Horizontal field of view in degrees (0.8 radians).
  for name, value in fields.items():
    block, _, field = name.rpartition(".")
    (data[block] if block else data)[field] = value
  return data


def data_spec(block, prefix="config.data"):
  """The `DataSpec` of a `data` block (the fields a job adds, such as `extent`, aside)."""
  syn = block.synthetic
  with translated({"SyntheticSpec": "synthetic"}, prefix):
    synthetic = SyntheticSpec(shape=syn.shape, num_gaussians=syn.num_gaussians,
                              seed=syn.seed, sh_degree=syn.sh_degree, radius=syn.radius,
                              cameras=syn.cameras, distance=syn.distance,
                              v_range=syn.v_range, fov_x_deg=syn.fov_x_deg)
  names = ("kind", "path", "downscale", "test_every", "holdout_every", "scene", "width",
           "height", "num_train", "num_test", "camera_seed", "spp", "cache_dir",
           "init_bounds", "progress")
  with translated({"DataSpec": ""}, prefix):
    return DataSpec(background=block.background, synthetic=synthetic,
                    **{n: block[n] for n in names})
