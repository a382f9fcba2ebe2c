"""The training config: every field of `train` and `train_and_evaluate`, with its default.

`default_config()` trains a stochastic Gaussian field on the built-in Mitsuba scene at
128 x 128. `configs/train.py` selects variants of it (lego, a tiny synthetic scene) on the
command line; any field is overridden there too, e.g. `--config.sampler.rank=4`.
Numbers without a comment on their origin follow 3DGS (Kerbl et al. 2023); those of B_hat
follow the authors' public code, where the paper is silent.
"""

import ml_collections
from ml_collections import config_dict

from mfsample.model import GROUPS


def default_config():
  """The training `ml_collections.ConfigDict` (see the comment on each field)."""
  config = ml_collections.ConfigDict()
  config.seed = 0  # Seeds everything: initial points, B_hat signs, z, view order, splits.

  # ----------------------------------------------------------------- data
  config.data = data = ml_collections.ConfigDict()  # Which views to train and test on.
  # "synthetic" (random Gaussians), "blender" (NeRF Synthetic), "scene" (Mitsuba), "colmap"
  # (a COLMAP capture: mfsample.data.load_colmap) or "llff" (mfsample.data.load_llff).
  data.kind = "scene"
  data.path = "data/nerf_synthetic/lego"  # blender, colmap, llff: scene folder (relative: cwd).
  # blender: integer image downscale factor (lego files are 400x400); colmap, llff: read the
  # pre-downscaled images_{downscale}/ folder (1: images/).
  data.downscale = 1
  data.test_every = 1  # blender: evaluate every n-th test view (1: all 200).
  # colmap, llff: every n-th image (by name, from the first) is a test view, the others train
  # (the Mip-NeRF 360 / 3DGS split: 8).
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
  # box), "points" (the dataset's SfM points and colours: data.kind "colmap") or "ply" (the
  # Gaussians of a trained 3DGS model, model.ply_path; model.sh_degree must match it).
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

  # ----------------------------------------------------------------- training
  config.train = train = ml_collections.ConfigDict()  # The loop.
  train.num_steps = 7_000  # Optimisation steps (3DGS: 30k; the planning protocol: 2000).
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
