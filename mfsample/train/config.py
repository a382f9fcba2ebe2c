"""The training config: every field of `train_and_evaluate`, with its default.

`default_config()` trains a stochastic Gaussian field on the built-in Mitsuba scene at
128 x 128. `configs/train.py` selects variants of it (lego, a tiny synthetic scene) on the
command line; any field is overridden there too, e.g. `--config.sampler.rank=4`.
Numbers without a comment on their origin follow 3DGS (Kerbl et al. 2023); those of B_hat
follow the authors' public code, where the paper is silent.
"""

import ml_collections
from ml_collections import config_dict

from mfsample import config_blocks as blocks
from mfsample import config_checks
from mfsample.model import group_shapes


def default_config():
  """The training `ml_collections.ConfigDict` (see the comment on each field)."""
  config = ml_collections.ConfigDict()
  config.seed = 0  # Seeds everything: initial points, B_hat signs, z, view order, splits.

  # Which views to train and test on (mfsample.data.DATA_KINDS).
  config.data = blocks.data_block(spp=36)
  config.data.extent = config_dict.placeholder(float)  # Scene extent; None: from the cameras.

  config.model = blocks.model_block()  # The Gaussians and their capacity.
  config.sampler = blocks.sampler_block()  # B_hat: theta(z) = mean + B_hat z.
  config.loss = blocks.loss_block()  # Eq. 9.
  config.optim = blocks.optim_block()  # Adam learning rates of the mean.
  config.densify = blocks.densify_block()  # 3DGS density control.
  config.render = blocks.render_block()  # Static renderer settings.

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


LPIPS_NETS = ("", "vgg16", "alexnet")


def validate(config, prefix="config"):
  """Checks every field of a training config; `ConfigError` naming the field and its range.

  The blocks read below the job are checked by building their settings (the one place of
  their rules: `mfsample.config_blocks`); the job's own fields here. Called by every job
  that trains (`prefix` names a nested training config: "config.round_train"). Fields are
  checked whatever `data.kind` is: a bad value is refused even where it would be unused, so
  a typo never lies dormant until a variant uses it.

  Returns:
    `config`.
  """
  c = config_checks
  kw = {"prefix": prefix}
  c.check_int(config, "seed", minimum=0, maximum=2**31 - 1, **kw)

  blocks.data_spec(config.data, f"{prefix}.data")
  init = blocks.init_settings(config.model, f"{prefix}.model")
  blocks.train_settings(config, prefix)
  blocks.sampler_spec(config.sampler, 1.0, group_shapes(init.sh_degree), f"{prefix}.sampler")

  c.check_int(config, "train.checkpoint_every", minimum=1, **kw)
  c.check_int(config, "train.keep_checkpoints", minimum=1, **kw)
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
  config.data.kind = "blender"  # The random initial points fill data.init_bounds.
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
  """Random ground-truth Gaussians: no files, no Mitsuba; under a minute on two CPU cores,
  nearly all of it compilation."""
  config.data.kind = "synthetic"  # Random Gaussians in [-0.6, 0.6]^3, 12 orbit views.
  config.data.width = config.data.height = 32
  config.data.num_train = 12
  config.data.num_test = 4
  config.data.background = (0.0, 0.0, 0.0)
  config.model.sh_degree = 0
  config.model.init_points = 300
  config.model.max_gaussians = 1024
  config.train.num_steps = 40
  config.train.checkpoint_every = 20
  config.train.log_every = 10
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
  """`default_config()` with the comma-separated `variant` names applied (`VARIANTS`)."""
  return config_checks.with_variants(default_config(), variant, VARIANTS, "configs/train.py")


# ----------------------------------------------------------------- translators


def train_spec(config, prefix="config"):
  """(`TrainSettings`, `InitSettings`) of a training config (the blocks' translators)."""
  return (blocks.train_settings(config, prefix),
          blocks.init_settings(config.model, f"{prefix}.model"))


def recipe(config, *, extent=None, init=None, prefix="config"):
  """The `mfsample.train.initial.Recipe` of a training config for a scene of `extent`
  (default: the config's `data.extent`, which must then be set); `init` replaces the
  `model` block's start (`InitSettings`)."""
  from mfsample.train.initial import Recipe

  settings, config_init = train_spec(config, prefix)
  init = config_init if init is None else init
  extent = settings.extent if extent is None else float(extent)
  if extent is None:
    raise ValueError(f"{prefix}.data.extent is None: the scene extent must be given")
  spec = blocks.sampler_spec(config.sampler, extent, group_shapes(init.sh_degree),
                             f"{prefix}.sampler")
  return Recipe(settings, init, spec, extent)
