"""Active camera planning on NeRF Synthetic lego: the selection strategies on a fixed pool.

Candidates = the 100 training views, test = the test split (every 4th of 200 views), at
80 x 80, with the main job's protocol (400-step rounds at 40 x 40, U with M = 8, 600
final steps). Lego has no ground-truth oracle for new poses, so the optimising variants
(Opt. Sel., Opt. Rnd.) are not run (paper Sec. 5.1 does the same for Mip-NeRF 360).
Three seeds (initial view, initialisation, random choices).

  python experiments/camera_planning.py --config=configs/camera_planning_lego.py \
      --workdir=workdirs/camera_planning_lego
"""

from configs import camera_planning


def get_config():
  config = camera_planning.get_config()
  config.seeds = (0, 1, 2)
  config.strategies = ("random", "farthest", "activenerf", "fisher", "acp", "ours_sel")
  config.data.kind = "blender"
  config.data.path = "../shared/data/lego"  # Relative to the repository root.
  config.data.downscale = 5  # The files are 400 x 400: 80 x 80 images.
  config.data.test_every = 4  # 50 of the 200 test views.
  config.data.bounds = (-1.3, 1.3)  # NeRF Synthetic's cube of random initial points.
  for t in (config.round_train, config.final_train):
    t.data.extent = 4.4  # 1.1 x the camera distance (4.03).
    t.model.init_points = 3_000  # More pixels than the default scene's 64 x 64.
    t.render.max_intersections = 1 << 15
  return config
