"""The training config: every field of `train` and `train_and_evaluate`, with its default.

`default_config()` trains a stochastic Gaussian field on the built-in Mitsuba scene at
128 x 128. `configs/train.py` selects variants of it (lego, a tiny synthetic scene) on the
command line; any field is overridden there too, e.g. `--config.sampler.rank=4`.
Numbers without a comment on their origin follow 3DGS (Kerbl et al. 2023); those of B_hat
follow the authors' public code, where the paper is silent.
"""

import ml_collections
from ml_collections import config_dict

from mfsample import config_checks
from mfsample.data import DATA_KINDS
from mfsample.model import GROUPS, SAMPLER_KINDS
from mfsample.renderer.settings import RenderSettings


def default_config():
  """The training `ml_collections.ConfigDict` (see the comment on each field)."""
  config = ml_collections.ConfigDict()
  config.seed = 0  # Seeds everything: initial points, B_hat signs, z, view order, splits.

  # ----------------------------------------------------------------- data
  config.data = data = ml_collections.ConfigDict()  # Which views to train and test on.
  # "synthetic" (random Gaussians), "blender" (NeRF Synthetic), "scene" (Mitsuba), "colmap"
  # (a COLMAP capture: mfsample.data.load_colmap), "llff" (mfsample.data.load_llff) or
  # "nerfstudio" (ns-process-data's transforms.json: mfsample.data.load_nerfstudio); the
  # kinds are mfsample.data.DATA_KINDS.
  data.kind = "scene"
  # blender, colmap, llff, nerfstudio: scene folder (relative: cwd).
  data.path = "data/nerf_synthetic/lego"
  # blender: integer image downscale factor (lego files are 400x400); colmap, llff,
  # nerfstudio: read the pre-downscaled images_{downscale}/ folder (1: images/).
  data.downscale = 1
  data.test_every = 1  # blender: evaluate every n-th test view (1: all 200).
  # colmap, llff, nerfstudio: every n-th image (by name, from the first) is a test view, the
  # others train (the Mip-NeRF 360 / 3DGS split: 8).
  data.holdout_every = 8
  data.scene = "default"  # scene: name for mfsample.scenes.get_scene.
  data.width = 128  # scene: image width in pixels.
  data.height = 128  # scene: image height in pixels.
  data.num_train = 100  # scene: training (candidate) cameras.
  data.num_test = 50  # scene: test cameras.
  data.spp = config_dict.placeholder(int)  # scene: samples per pixel (None: the default).
  data.cache_dir = config_dict.placeholder(str)  # scene: capture cache (None: the default).
  data.background = (1.0, 1.0, 1.0)  # Colour behind the Gaussians, as in the images.
  # Cube of the random initial point cloud (NeRF Synthetic; kind "scene" uses the cube
  # around the scene's bounding sphere instead).
  data.init_bounds = (-1.3, 1.3)
  data.extent = config_dict.placeholder(float)  # Scene extent; None: from the cameras (3DGS).
  data.synthetic = syn = ml_collections.ConfigDict()  # kind "synthetic": random Gaussians.
  syn.num_gaussians = 200  # Ground-truth Gaussians of the synthetic scene.
  syn.sh_degree = 0  # Their SH degree.
  syn.num_train = 12  # Training views.
  syn.num_test = 4  # Test views.
  syn.width = 32  # Image width in pixels.
  syn.height = 32  # Image height in pixels.
  syn.distance = 3.0  # Camera distance from the origin.
  syn.seed = 0  # Seed of the ground-truth Gaussians.

  # ----------------------------------------------------------------- model
  config.model = model = ml_collections.ConfigDict()  # The Gaussians and their capacity.
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

  # ----------------------------------------------------------------- sampler (B_hat)
  config.sampler = sampler = ml_collections.ConfigDict()  # theta(z) = mean + B_hat z.
  sampler.kind = "lowrank"  # "lowrank" (paper), "block", "diagonal" or "deterministic".
  sampler.rank = 2  # k, columns of B_hat (paper default 2); also the rank of each block.
  sampler.groups = GROUPS  # Stochastic parameter groups (others are deterministic).
  sampler.num_samples = 1  # M, samples rendered per training step (paper: 1).
  # Steps that render samples; later steps render the mean (the volume term goes on).
  # None: every step (the paper's text). The authors' code: 3000 (the first opacity reset).
  sampler.stochastic_until = config_dict.placeholder(int)
  sampler.z = "sobol"  # lowrank z source: "sobol" (scrambled, paper) or "uniform".
  sampler.z_seed = 6174  # Scrambling seed of the Sobol sequence (authors' code: 6174).
  sampler.init_scale = 1e-3  # Raw B_hat entries start at init_scale * U[0, 1] ...
  sampler.init_extent_groups = ("means", "log_scales")  # ... times extent for these groups.
  sampler.bounds = bounds = ml_collections.ConfigDict()  # relu(raw) is kept in [0, bound].
  bounds.means = 1.0  # Centres, in units of the scene extent.
  bounds.log_scales = 20.0  # Log-scales.
  bounds.quats = 2.0  # Raw quaternion components.
  bounds.opacity_logits = 20.0  # Opacity logits.
  bounds.sh_dc = 0.5  # SH DC coefficients.
  bounds.sh_rest = 0.5  # Higher SH coefficients.
  sampler.lr = lr = ml_collections.ConfigDict()  # Adam learning rates of raw B_hat entries.
  lr.means = 1.6e-5  # Centres, times the scene extent; constant (only the mean's decay).
  lr.log_scales = 5e-4  # Log-scales.
  lr.quats = 1e-4  # Quaternions.
  lr.opacity_logits = 5e-3  # Opacity logits.
  lr.sh_dc = 2.5e-3  # SH DC.
  lr.sh_rest = 1.25e-4  # Higher SH bands.

  # ----------------------------------------------------------------- loss (Eq. 9)
  config.loss = loss = ml_collections.ConfigDict()  # Eq. 9.
  loss.ssim_weight = 0.2  # w in (1 - w) L1 + w (1 - SSIM).
  # lambda of the volume term on the plain sum of |B_hat|. None: 1 / (training views), as
  # in the authors' code; the paper's text says 1 (docs/training.md).
  loss.volume_weight = config_dict.placeholder(float)
  loss.volume_every = 10  # The volume term is applied on every 10th step only (paper).
  loss.volume_stop_before_end = 100  # No volume term in the last steps (authors' code).

  # ----------------------------------------------------------------- optimiser (mean)
  config.optim = optim = ml_collections.ConfigDict()  # Adam learning rates of the mean.
  optim.position_lr_init = 1.6e-4  # Times extent; decays exponentially ...
  optim.position_lr_final = 1.6e-6  # ... to this (times extent) ...
  optim.position_lr_max_steps = config_dict.placeholder(int)  # ... over this (None: all).
  optim.log_scales = 5e-3  # Log-scales.
  optim.quats = 1e-3  # Quaternions.
  optim.opacity_logits = 0.05  # Opacity logits.
  optim.sh_dc = 2.5e-3  # SH DC ("feature" lr of 3DGS).
  optim.sh_rest = 1.25e-4  # Higher SH bands (3DGS: feature lr / 20).

  # ----------------------------------------------------------------- densification
  config.densify = densify = ml_collections.ConfigDict()  # 3DGS density control.
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

  # ----------------------------------------------------------------- render budget
  config.render = render = ml_collections.ConfigDict()  # Static renderer settings.
  render.max_intersections = 1 << 16  # Initial budget; grown (power of 2) on overflow.
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

  # ----------------------------------------------------------------- training
  config.train = train = ml_collections.ConfigDict()  # The loop.
  train.num_steps = 7_000  # Optimisation steps (3DGS: 30k; the planning protocol: 2000).
  # Views per step (data-parallel: split over the devices of every process, gradients
  # averaged, docs/scaling.md). The schedules count steps, so B > 1 sees B times as many
  # views in num_steps; 1 is the single-view step of 3DGS.
  train.batch_size = 1
  train.checkpoint_every = 500  # Checkpoint period in steps (and at the end).
  train.keep_checkpoints = 2  # Older checkpoints are deleted.
  train.log_every = 100  # Progress-bar and log period in steps.
  train.progress = True  # Show a tqdm progress bar.

  # ----------------------------------------------------------------- evaluation
  config.eval = ev = ml_collections.ConfigDict()  # Test metrics and outputs.
  ev.lpips_net = "vgg16"  # LPIPS network ("vgg16" as in 3DGS, "alexnet"; "" to skip).
  ev.uncertainty_samples = 2  # Samples of the per-pixel uncertainty maps (paper: M = 2).
  ev.save_images = 8  # Test views whose render / ground truth / uncertainty are written.
  ev.export_ply = True  # Write the mean model as point_cloud.ply (3DGS layout).
  return config


INIT_FROM = ("random", "points", "ply")  # mfsample.train.initial
LPIPS_NETS = ("", "vgg16", "alexnet")
COMPOSITORS = ("jnp", "pallas")  # mfsample.renderer.settings.RenderSettings.compositor

# Fields that change only how fast a run goes, never what it computes (beyond float
# rounding): a resumed run or a reused result may differ in them.
SPEED_ONLY_FIELDS = ("render.chunks_per_step", "render.compositor")


def speed_only_fields(prefix=""):
  """`SPEED_ONLY_FIELDS` of a training config found at `prefix` ("round_train") of another."""
  return tuple(f"{prefix}.{f}" if prefix else f for f in SPEED_ONLY_FIELDS)


def render_settings(render_config):
  """`RenderSettings` of a config's `render` block.

  The initial budget is rounded up to a whole number of compositing steps
  (chunk_size x chunks_per_step), so any `chunks_per_step` is valid with any start.
  """
  chunks_per_step = int(render_config.get("chunks_per_step", RenderSettings.chunks_per_step))
  return RenderSettings.holding(
      render_config.max_intersections, tile_size=int(render_config.tile_size),
      chunks_per_step=chunks_per_step,
      radius_sigma=float(render_config.get("radius_sigma", RenderSettings.radius_sigma)),
      compositor=str(render_config.get("compositor", RenderSettings.compositor)))


def validate_render(config, prefix="config"):
  """Checks a config's `render` block (`render_settings` reads it); `ConfigError` names the
  field. Every config that trains or renders has one."""
  kw = {"prefix": prefix}
  c = config_checks
  c.check_int(config, "render.max_intersections", minimum=1, **kw)
  c.check_int(config, "render.max_budget", minimum=1, **kw)
  c.check_order(config, "render.max_intersections", "render.max_budget", **kw)
  c.check_int(config, "render.tile_size", minimum=1, **kw)
  if "chunks_per_step" in config.render:
    c.check_int(config, "render.chunks_per_step", minimum=1, **kw)
  c.check_float(config, "render.radius_sigma", above=0.0, **kw)
  c.check_choice(config, "render.compositor", COMPOSITORS, **kw)


def validate(config, prefix="config"):
  """Checks every field of a training config; `ConfigError` naming the field and its range.

  Called by `train` and `train_and_evaluate` before anything is computed or written, and by
  the planning protocol for its round and final training configs (`prefix` names them:
  "config.round_train"). Fields are checked whatever `data.kind` is: a bad value is refused
  even where it would be unused, so a typo never lies dormant until a variant uses it.

  Returns:
    `config`.
  """
  c = config_checks
  kw = {"prefix": prefix}
  c.check_int(config, "seed", minimum=0, maximum=2**31 - 1, **kw)

  c.check_choice(config, "data.kind", tuple(DATA_KINDS), **kw)
  c.check_str(config, "data.path", **kw)
  c.check_int(config, "data.downscale", minimum=1, **kw)
  c.check_int(config, "data.test_every", minimum=1, **kw)
  c.check_int(config, "data.holdout_every", minimum=2, **kw)
  c.check_str(config, "data.scene", non_empty=True, **kw)
  for field in ("width", "height", "num_train", "num_test"):
    c.check_int(config, f"data.{field}", minimum=1, **kw)
  c.check_int(config, "data.spp", minimum=1, optional=True, **kw)
  c.check_str(config, "data.cache_dir", optional=True, **kw)
  c.check_floats(config, "data.background", 3, minimum=0.0, maximum=1.0, **kw)
  c.check_floats(config, "data.init_bounds", 2, increasing=True, **kw)
  c.check_float(config, "data.extent", above=0.0, optional=True, **kw)
  for field in ("num_gaussians", "num_train", "num_test", "width", "height"):
    c.check_int(config, f"data.synthetic.{field}", minimum=1, **kw)
  c.check_int(config, "data.synthetic.sh_degree", minimum=0, maximum=3, **kw)
  c.check_float(config, "data.synthetic.distance", above=0.0, **kw)
  c.check_int(config, "data.synthetic.seed", minimum=0, **kw)

  c.check_int(config, "model.sh_degree", minimum=0, maximum=3, **kw)
  c.check_int(config, "model.init_points", minimum=1, **kw)
  init_from = c.check_choice(config, "model.init_from", INIT_FROM, **kw)
  ply_path = c.check_str(config, "model.ply_path", **kw)
  if init_from == "ply" and not ply_path:
    raise c.ConfigError(f"{prefix}.model.init_from = 'ply' needs {prefix}.model.ply_path, the "
                        "3DGS point_cloud.ply to start from")
  c.check_float(config, "model.init_opacity", above=0.0, below=1.0, **kw)
  c.check_int(config, "model.max_gaussians", minimum=1, **kw)

  c.check_choice(config, "sampler.kind", SAMPLER_KINDS, **kw)
  c.check_int(config, "sampler.rank", minimum=1, **kw)
  c.check_sequence(config, "sampler.groups", item_choices=GROUPS, min_length=0, distinct=True,
                   **kw)
  c.check_int(config, "sampler.num_samples", minimum=1, **kw)
  c.check_int(config, "sampler.stochastic_until", minimum=0, optional=True, **kw)
  c.check_choice(config, "sampler.z", ("sobol", "uniform"), **kw)
  c.check_int(config, "sampler.z_seed", minimum=0, maximum=2**32 - 1, **kw)
  c.check_float(config, "sampler.init_scale", minimum=0.0, **kw)
  c.check_sequence(config, "sampler.init_extent_groups", item_choices=GROUPS, min_length=0,
                   distinct=True, **kw)
  for group in GROUPS:
    c.check_float(config, f"sampler.bounds.{group}", above=0.0, **kw)
    c.check_float(config, f"sampler.lr.{group}", minimum=0.0, **kw)

  c.check_float(config, "loss.ssim_weight", minimum=0.0, maximum=1.0, **kw)
  c.check_float(config, "loss.volume_weight", minimum=0.0, optional=True, **kw)
  c.check_int(config, "loss.volume_every", minimum=1, **kw)
  c.check_int(config, "loss.volume_stop_before_end", minimum=0, **kw)

  c.check_float(config, "optim.position_lr_init", above=0.0, **kw)  # log-linear decay
  c.check_float(config, "optim.position_lr_final", above=0.0, **kw)
  c.check_int(config, "optim.position_lr_max_steps", minimum=1, optional=True, **kw)
  for group in GROUPS[1:]:
    c.check_float(config, f"optim.{group}", minimum=0.0, **kw)

  for field in ("start", "stop", "prune_big_after"):
    c.check_int(config, f"densify.{field}", minimum=0, **kw)
  for field in ("every", "opacity_reset_every", "sh_degree_every"):
    c.check_int(config, f"densify.{field}", minimum=1, **kw)
  c.check_float(config, "densify.grad_threshold", minimum=0.0, **kw)
  c.check_float(config, "densify.percent_dense", minimum=0.0, **kw)
  c.check_float(config, "densify.min_opacity", minimum=0.0, below=1.0, **kw)
  c.check_float(config, "densify.max_world_size", above=0.0, **kw)
  c.check_float(config, "densify.max_screen_size", minimum=0.0, **kw)

  validate_render(config, prefix)

  c.check_int(config, "train.num_steps", minimum=1, **kw)
  c.check_int(config, "train.batch_size", minimum=1, **kw)
  c.check_int(config, "train.checkpoint_every", minimum=1, **kw)
  c.check_int(config, "train.keep_checkpoints", minimum=1, **kw)
  c.check_int(config, "train.log_every", minimum=1, **kw)
  c.check_bool(config, "train.progress", **kw)

  c.check_choice(config, "eval.lpips_net", LPIPS_NETS, **kw)
  samples = c.check_int(config, "eval.uncertainty_samples", minimum=0, **kw)
  if samples == 1:  # the variance of one sample is 0: an all-zero map, not an estimate
    raise config_checks.ConfigError(f"{prefix}.eval.uncertainty_samples = 1: must be 0 (no "
                                    "uncertainty maps) or >= 2")
  c.check_int(config, "eval.save_images", minimum=0, **kw)
  c.check_bool(config, "eval.export_ply", **kw)
  return config


# ----------------------------------------------------------------- variants


def lego(config):
  """Lego at 200 x 200: 3DGS's schedules compressed to the step budget of a 2-core CPU."""
  config.data.kind = "blender"
  config.data.downscale = 2  # The 400 x 400 files (a 2x box filter of 800 x 800) halved.
  config.data.background = (1.0, 1.0, 1.0)  # White, the 3DGS convention for lego.
  # 3DGS: 100k points at 800^2. 200^2 has 16x fewer pixels; 10k points in [-1.3, 1.3]^3
  # keep ~4 initial points per pixel column through the object.
  config.model.init_points = 10_000
  config.model.max_gaussians = 60_000
  config.train.num_steps = 5_000
  # 3DGS densifies for the first half of 30k steps and resets opacities every 3000; with
  # 5000 steps the reset stays at 3000 and densification stops at 3500.
  config.densify.stop = 3_500
  # Samples are rendered until the first opacity reset, then the mean (the volume term goes
  # on), as the authors' code does for its all-view models: the mean then reaches nearly
  # the quality of deterministic 3DGS (docs/training.md).
  config.sampler.stochastic_until = 3_000
  config.render.max_intersections = 1 << 17


def tiny(config):
  """Random ground-truth Gaussians: no files, no Mitsuba, a few seconds."""
  config.data.kind = "synthetic"
  config.data.background = (0.0, 0.0, 0.0)
  config.data.init_bounds = (-0.8, 0.8)  # The ground truth lives in [-0.6, 0.6]^3.
  config.model.sh_degree = 0
  config.model.init_points = 300
  config.model.max_gaussians = 1024
  config.train.num_steps = 40
  config.train.checkpoint_every = 20
  config.train.log_every = 10
  config.train.progress = False
  config.densify.start = 10
  config.densify.every = 10
  config.densify.stop = 30
  config.densify.opacity_reset_every = 1000
  config.densify.sh_degree_every = 10
  config.loss.volume_stop_before_end = 2  # (Short runs keep the volume term.)
  config.render.max_intersections = 1 << 12
  config.eval.lpips_net = ""  # No VGG pass in quick runs.
  config.eval.save_images = 2


VARIANTS = {f.__name__: f for f in (lego, tiny)}


def get_config(variant=""):
  """`default_config()` with the comma-separated `variant`s applied (`VARIANTS`)."""
  return config_checks.with_variants(default_config(), variant, VARIANTS, "configs/train.py")
