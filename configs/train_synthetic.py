"""A seconds-long run on random ground-truth Gaussians (no files, no Mitsuba): tests, CI."""

from configs import train_default


def get_config():
  config = train_default.get_config()
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
  config.eval.lpips_net = ""  # No network download or VGG pass in quick runs.
  config.eval.save_images = 2
  return config
