"""Active camera planning: `experiments/camera_planning.py --config=configs/camera_planning.py`.

Without a variant this is the main job: every strategy of the paper's Table 1 on the
built-in Mitsuba scene, one seed, about 20 minutes on two CPU cores (the defaults and a
comment on every field: `mfsample.planning.config`). Variants combine, comma-separated,
e.g. `--config=configs/camera_planning.py:lego,rounds2000`:

  lego             NeRF Synthetic lego at 80 x 80: candidates = its 100 training views,
                   test = every 4th test view; selection strategies only (no oracle).
                   Point `--config.data.path` at the scene folder.
  rounds2000       the paper's round length: 2000 steps per round instead of 400.
  authors_rounds   round models as the authors train them: densification, lambda = 1 / views.
  fullres          round models trained, and candidates scored, at the test resolution.
  densified_final  final models trained 2000 steps with 3DGS densification.
  paper_scale      lego's final models at the paper's scale (400 x 400, 100k points, 7000
                   densified steps; a GPU job), on round models at 40 x 40.
  tiny             seconds-long: random ground-truth Gaussians at 24 x 24, 3 views.

Seeds and strategies are overrides, e.g. `--config.seeds="(0,1,2,3,4,5,6,7)"
--config.strategies="('farthest','ours_sel')"`; docs/camera_planning.md lists each study.
"""

from mfsample.planning.config import default_config

SELECTION_STRATEGIES = ("random", "farthest", "activenerf", "fisher", "acp", "ours_sel")


def get_config(variant=""):
  config = default_config()
  for name in filter(None, (v.strip() for v in variant.split(","))):
    if name not in VARIANTS:
      raise ValueError(f"unknown variant {name!r} of configs/camera_planning.py; known: "
                       f"{', '.join(VARIANTS)}")
    VARIANTS[name](config)
  return config


def lego(config):
  """NeRF Synthetic lego on a fixed pool, at 80 x 80 (rounds and scoring at 40 x 40)."""
  config.strategies = SELECTION_STRATEGIES
  config.data.kind = "blender"
  for t in (config.round_train, config.final_train):
    t.data.extent = 4.4  # 1.1 x the camera distance (4.03).
    t.model.init_points = 3_000  # More pixels than the default scene's 64 x 64.
    t.render.max_intersections = 1 << 15


def rounds2000(config):
  """The paper's round length: every re-initialised round model trains 2000 steps."""
  config.rounds.steps = 2000
  config.round_train.loss.volume_stop_before_end = 100  # The authors' value at 2000 steps.


def authors_rounds(config):
  """Round models with the authors' recipe: 3DGS densification from step 500 to the end of
  the round and the volume weight lambda = 1 / (number of training views)."""
  d = config.round_train.densify
  d.start = 500
  d.every = 100
  d.stop = config.rounds.get_ref("steps")
  d.opacity_reset_every = 3_000  # The authors' period: no reset within a 2000-step round.
  config.round_train.model.max_gaussians = 20_000
  config.round_train.loss.volume_weight = None  # 1 / the number of training views.


def fullres(config):
  """Round models train on, and candidates are scored at, the test resolution."""
  config.rounds.downscale = 1
  config.strategy.score_downscale = 1


def densified_final(config, steps=2000, max_gaussians=20_000):
  """Final models trained `steps` steps with 3DGS densification (every 100 steps from step
  500 to the end, no opacity reset before step 3000)."""
  t = config.final_train
  t.train.num_steps = steps
  t.train.log_every = steps
  t.densify.start = 500
  t.densify.every = 100
  t.densify.stop = steps
  t.densify.opacity_reset_every = 3_000
  t.model.max_gaussians = max_gaussians


def paper_scale(config):
  """Lego's final models as the authors train them, on the round models of lego,rounds2000
  (40 x 40): the files' 400 x 400 images, 100k random initial points, SH degree 3, 7000
  steps with densification and opacity resets."""
  lego(config)
  rounds2000(config)
  config.strategies = ("farthest", "ours_sel")
  config.data.downscale = 1
  config.rounds.downscale = 10
  config.strategy.score_downscale = 10
  densified_final(config, steps=7_000, max_gaussians=300_000)
  t = config.final_train
  t.densify.sh_degree_every = 1_000
  t.model.sh_degree = 3
  t.model.init_points = 100_000
  t.render.max_intersections = 1 << 20
  t.render.max_budget = 1 << 26


def tiny(config):
  """24 x 24 images of random ground-truth Gaussians, 8 candidates, 3 views, a few steps."""
  config.eval_views = (2, 3)
  config.max_views = 3
  config.progress = False
  config.data.kind = "synthetic"
  config.data.width = 24
  config.data.height = 24
  config.data.num_candidates = 8
  config.data.num_test = 2
  config.data.background = (0.0, 0.0, 0.0)
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


VARIANTS = {f.__name__: f for f in (lego, rounds2000, authors_rounds, fullres, densified_final,
                                    paper_scale, tiny)}
