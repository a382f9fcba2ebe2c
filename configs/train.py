"""Training a stochastic Gaussian field: `experiments/train.py --config=configs/train.py:VARIANT`.

Variants (the defaults and a comment on every field: `mfsample.train.config`):

  (none)  the built-in Mitsuba scene at 128 x 128, 7000 steps with densification.
  lego    NeRF Synthetic lego at 200 x 200 on white, all 100 training views, 5000 steps.
          Point `--config.data.path` at the scene folder (default data/nerf_synthetic/lego).
  tiny    seconds-long: random ground-truth Gaussians at 32 x 32, 40 steps (tests, smoke runs).

Any field is overridden on the command line, e.g. `--config.sampler.rank=4`.
"""

from mfsample.train.config import default_config


def get_config(variant=""):
  config = default_config()
  if variant == "lego":
    _lego(config)
  elif variant == "tiny":
    _tiny(config)
  elif variant:
    raise ValueError(f"unknown variant {variant!r} of configs/train.py; known: lego, tiny")
  return config


def _lego(config):
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


def _tiny(config):
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
