"""Lego (NeRF Synthetic) at 200 x 200 on a white background, all 100 training views.

Schedules are those of 3DGS compressed to the step budget of a 2-core CPU.
"""

from configs import train_default


def get_config():
  config = train_default.get_config()
  config.data.kind = "blender"
  config.data.path = "../shared/data/lego"  # 400 x 400 files (a 2x box filter of 800 x 800).
  config.data.downscale = 2  # 200 x 200.
  config.data.background = (1.0, 1.0, 1.0)  # White, the 3DGS convention for lego.
  # 3DGS: 100k points at 800^2. 200^2 has 16x fewer pixels; 10k points in [-1.3, 1.3]^3
  # keep ~4 init points per pixel column through the object and fit the CPU budget.
  config.model.init_points = 10_000
  config.model.max_gaussians = 60_000
  config.train.num_steps = 5_000
  # 3DGS densifies for the first half of 30k steps and resets opacities every 3000; with
  # 5000 steps we keep the absolute reset at 3000 and densify until 3500.
  config.densify.stop = 3_500
  # Render samples until the first opacity reset, then the mean, as the authors' code does
  # for its all-view models (the volume term goes on). Measured at 100 x 100, 5000 steps
  # (benchmarks/train_quality.py): the rank-2 mean reaches 31.60 dB against 32.01 for
  # deterministic 3DGS; sampling at every step (the paper's text) reaches 25.31 dB.
  # Planning rounds sample at every step (their U is what they are for).
  config.sampler.stochastic_until = 3_000
  config.render.max_intersections = 1 << 17
  return config
