"""A seconds-long planning run on random ground-truth Gaussians (no files, no Mitsuba).

Tests and the notebook use it: 24 x 24 images, 8 candidates, 3 views, a few steps.
"""

from configs import camera_planning


def get_config():
  config = camera_planning.get_config()
  config.eval_views = (2, 3)
  config.max_views = 3
  config.progress = False
  config.data.kind = "synthetic"
  config.data.width = 24
  config.data.height = 24
  config.data.num_candidates = 8
  config.data.num_test = 2
  config.data.background = (0.0, 0.0, 0.0)
  config.data.synthetic = s = config.data.__class__()
  s.shape = "shell"  # Ground truth: an opaque shell ("shell") or a see-through "cloud".
  s.num_gaussians = 150  # Ground-truth Gaussians.
  s.seed = 0  # Their seed.
  s.radius = 0.5  # Radius of the shell (half-side of the cloud's cube).
  s.distance = 3.0  # Camera sphere radius.
  s.v_range = (0.1, 0.6)  # Polar band of the cameras (v = polar / pi).
  s.fov_x_deg = 40.0  # Horizontal field of view.
  for t in (config.round_train, config.final_train):
    t.model.init_points = 150
    t.model.max_gaussians = 512
    t.data.extent = 3.3
    t.render.max_intersections = 1 << 11
  config.rounds.first_steps = 100
  config.rounds.steps = 100
  config.rounds.downscale = 1
  config.final_train.train.num_steps = 12
  config.round_train.loss.volume_every = 3
  config.strategy.optimize.steps = 12
  config.strategy.optimize.lr = 1e-2
  config.strategy.optimize.z_drop_step = 8
  config.strategy.activenerf.steps = 4
  config.strategy.fisher.train_probes = 2
  config.strategy.acp.resolution = 8
  config.eval.lpips_net = ""
  config.figures.landscape_u = 6
  config.figures.landscape_v = 3
  return config
