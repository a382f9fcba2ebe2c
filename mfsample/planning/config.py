"""The active camera planning protocol's config, with its defaults (the main job).

`default_config()` runs every strategy of the paper's Table 1 on the built-in Mitsuba scene
(`mfsample.scenes.get_scene("default")`), one seed, scaled so that the whole run, first-time
captures included, fits in about 20 minutes on two CPU cores. The paper's protocol at
800 x 800 on a GPU: 2000 steps per round, 7000 final steps, 100k initial points. Here:
64 x 64 images, 2000 initial points, no densification, 400 steps per (re-initialised)
round at 32 x 32, where candidates are also scored (U with M = 8 samples), and 600 final
steps. `configs/camera_planning.py` selects variants (lego, the paper's round length, a
tiny synthetic scene) on the command line; every number is a field below.
"""

import ml_collections

from mfsample import config_blocks as blocks
from mfsample import config_checks
from mfsample.config_blocks import data_spec, from_block
from mfsample.data import FILE_KINDS
from mfsample.planning import strategies as st
from mfsample.planning.strategies import NAMES, STRATEGIES, TABLE1_NAMES
from mfsample.train.config import LPIPS_NETS
from mfsample.train.config import default_config as training_config
from mfsample.train.config import validate as validate_training


def _training(steps, kind):
  """A training config for `steps` steps without densification.

  `steps` may be a `FieldReference` (the rounds pass `rounds.steps`'s): num_steps then
  follows it, and log_every follows it until a config sets its own.
  """
  t = training_config()
  t.sampler.kind = kind  # Rounds of Ours: "lowrank"; the baselines' rounds set their own.
  t.sampler.rank = 2  # k = 2, the paper's default.
  t.model.sh_degree = 0  # View-independent colour: < 1000 steps never raise the SH degree.
  t.model.init_points = 2_000  # Random initial points in the scene box (no SfM).
  t.model.max_gaussians = 8_000
  t.train.num_steps = steps
  t.train.progress = False
  t.train.log_every = steps * 1  # A derived reference: setting it leaves num_steps alone.
  t.densify.start = 100_000  # No densification (static shapes: one compilation per kind).
  t.densify.stop = 100_000
  t.densify.opacity_reset_every = 100_000
  t.data.background = (1.0, 1.0, 1.0)
  # 3DGS derives the extent from the training cameras; fixed here so that it does not
  # change (and recompile the step) every round: 1.1 x the camera distance of the scene.
  t.data.extent = 3.3
  # lambda of the volume term. The authors use 1 / (number of views), with 2000+ steps per
  # round and densification (whose fresh B_hat entries keep observed regions certain). In
  # a few hundred steps without densification that weight swamps the data term in Adam's
  # normalisation: every B_hat entry then grows at the same rate, seen or not (measured),
  # and U only measures how much of the scene a view sees. At 1e-4 the data gradients of
  # observed Gaussians dominate their Adam denominators and slow their growth: U is low
  # near the training views and high away from them (tests/core/test_uncertainty.py).
  t.loss.volume_weight = 1e-4
  t.loss.volume_stop_before_end = 10  # Authors: the last 100 of 2000 steps; scaled.
  t.render.max_intersections = 1 << 14  # Initial budget (grown on overflow).
  t.eval.lpips_net = ""
  return t


def default_config():
  """The planning `ml_collections.ConfigDict` (see the comment on each field)."""
  config = ml_collections.ConfigDict()
  config.seeds = (0,)  # Seeds: initial view, model initialisation, random choices.
  config.strategies = TABLE1_NAMES  # random, farthest, activenerf, fisher, acp, ours x3.
  config.initial_view = -1  # Candidate index of the first view; < 0: a seeded random one.
  config.eval_views = (5, 10)  # Evaluate after this many views (paper: 5 and 10).
  config.max_views = 10  # Views at the end of a run (the largest of eval_views).
  config.progress = True  # tqdm progress bar.
  # With several seeds, table.md also lists every strategy's PSNR difference to each of
  # these, paired by seed (same initial view and initialisation).
  config.paired_references = ("farthest", "fisher", "ours_sel")

  # ----------------------------------------------------------------- data
  # The pool: a dataset of any kind (mfsample.data.DATA_KINDS). Its training views are the
  # candidates (data.num_train: paper, the 100 training views), its test views held out. The
  # built-in scene ("scene") and "synthetic" Gaussians capture any new pose; files
  # ("blender", "colmap", "llff", "nerfstudio") are fixed pools, where only the selection
  # strategies run (a capture's sparse points serve round models whose
  # round_train.model.init_from is "points"). Defaults: 64 x 64 (paper: 800), 100
  # candidates, 40 test views; lego's 400 x 400 files downscaled 5x (80 x 80), every 4th of
  # its test views; the synthetic scene an opaque shell seen from a polar band.
  config.data = blocks.data_block(
      width=64, height=64, num_train=100, num_test=40, downscale=5, test_every=4,
      **{"synthetic.shape": "shell", "synthetic.num_gaussians": 150, "synthetic.radius": 0.5,
         "synthetic.cameras": "band", "synthetic.fov_x_deg": 40.0})

  # ----------------------------------------------------------------- training
  config.rounds = rounds = ml_collections.ConfigDict()
  # The paper's text: one training run, a camera added every 2000 iterations (warm start).
  # The authors' code: every round re-initialises the model and trains 2000 iterations.
  # Warm start gives better-trained round models for the same CPU time; False: the code's.
  rounds.warm_start = False
  rounds.first_steps = 400  # Steps of the first round (warm start only).
  # Steps of every later round (re-initialised: of every round). Longer rounds make U
  # follow the round model's error at the candidates better (docs/tradeoffs.md); 400 keeps
  # the main job inside 20 minutes, the paper's 2000 is the variant "rounds2000".
  rounds.steps = 400
  # The round models only rank views: they train on 2x downscaled images (32 x 32), the
  # resolution at which candidates are scored (`strategy.score_downscale`).
  rounds.downscale = 2
  # The training config of the rounds; its num_steps is `rounds.steps` (one field: setting
  # either sets both; with warm_start the runner spans it over all rounds). Ours: lowrank.
  config.round_train = _training(rounds.get_ref("steps"), "lowrank")
  # Final plain 3DGS (authors: 7000). Test PSNR still rises past 600 steps; the budget is
  # the main job's 20 minutes.
  config.final_train = _training(600, "deterministic")

  # ----------------------------------------------------------------- strategies
  config.strategy = s = ml_collections.ConfigDict()
  # Candidates are scored (U, FisherRF, ActiveNeRF) at 1 / score_downscale of the image
  # size, the same for every strategy: a ranking needs fewer pixels than a reconstruction.
  s.score_downscale = 2
  s.ours = ours = ml_collections.ConfigDict()
  # M for Ours (Sel.) scoring (paper: 2). At 32 x 32 eight samples cost little and rank the
  # candidates as a 32-sample U does better than two (docs/tradeoffs.md).
  ours.select_samples = 8
  ours.z_seed = 6174  # Sobol scrambling seed of the U samples (authors' code: 6174).
  ours.chunk_size = 1  # Candidates vmapped together (1: sequential, cheapest on a CPU).
  ours.score_downscale = s.get_ref("score_downscale")
  s.optimize = opt = ml_collections.ConfigDict()
  opt.samples = 2  # M during optimisation (paper: 2).
  # Authors: 400 Adam steps at lr 5e-4, z x 0.1 from step 200 (u, v travel <= 0.2). Scaled
  # to 60 steps at lr 3.3e-3: the same maximum travel in 15% of the time.
  opt.steps = 60
  opt.lr = 3.3e-3
  opt.z_drop_step = 30
  opt.z_drop_scale = 0.1
  opt.downscale = 2  # The optimisation renders at 1/2 of the image size (speed).
  # False: the same M Sobol z at every step (the paper's). True: M fresh uniform z per step,
  # stochastic gradients of the expected U (`optimize.OptimizeSettings.resample_z`).
  opt.resample_z = False
  # The round model of the optimising variants: "" = the rounds' sampler (lowrank, the
  # paper's). The authors' published optimisation command trains rank 0, i.e. "diagonal",
  # with fresh z every step.
  opt.sampler = ""
  # Ours (Opt. Best) scores every best_every-th pose of the ascent (and its end) as the
  # candidates are scored, and keeps the best of them and the start: 6 extra scorings here.
  opt.best_every = 10
  s.fisher = fisher = ml_collections.ConfigDict()
  fisher.probes = 1  # Rademacher probes (backward passes) per candidate.
  fisher.train_probes = 8  # Probes per training view (H_train is in a denominator).
  fisher.reg = 1e-6  # lambda of sum H_cand / (H_train + lambda) (FisherRF).
  fisher.groups = ("means", "log_scales", "opacity_logits", "sh_dc", "sh_rest")  # No rotations.
  fisher.score_downscale = s.get_ref("score_downscale")
  s.activenerf = an = ml_collections.ConfigDict()
  an.steps = 40  # Adam steps of the per-Gaussian log-variance fit (one view each).
  an.lr = 0.05  # Its learning rate.
  an.prior_var = 0.05  # Variance of Gaussians no view constrains.
  an.beta_min = 1e-3  # Variance floor of every pixel.
  an.prior_weight = 1e-3  # Weight of the quadratic prior on the log-variance.
  an.score_downscale = s.get_ref("score_downscale")
  s.acp = acp = ml_collections.ConfigDict()
  acp.resolution = 32  # Grid cells per axis (Kopanas & Drettakis: 32^3).
  acp.bins = 64  # Direction bins (Fibonacci sphere).
  acp.weight = 1.0  # Weight of angular uniformity against coverage.
  acp.near = 0.2  # Cells nearer than this (camera z) are not observed.

  # ----------------------------------------------------------------- evaluation, figures
  config.eval = ev = ml_collections.ConfigDict()
  ev.lpips_net = "vgg16"  # LPIPS network ("vgg16" as in 3DGS and the paper; "" to skip).
  config.figures = fig = ml_collections.ConfigDict()
  fig.enabled = True  # Write cameras.png and landscape.png.
  fig.landscape_u = 36  # Azimuth samples of the landscape grid.
  fig.landscape_v = 10  # Polar samples of the landscape grid.
  fig.landscape_trajectory = True  # Trace an optimisation from a random start on it.
  return config


def validate(config):
  """Checks every field of a planning config; `ConfigError` naming the field and its range.

  `run_camera_planning` calls it before anything is written. Seeds and strategies must be
  distinct (a repeated seed would count one run twice in the means and standard errors), the
  evaluation counts must lie within `max_views`, and the round and final training configs
  are checked by `mfsample.train.config.validate` as `config.round_train` /
  `config.final_train`.

  Returns:
    `config`.
  """
  c = config_checks
  c.check_sequence(config, "seeds", item_minimum=0, distinct=True)
  for i, seed in enumerate(config.seeds):
    if seed > 2**31 - 1:
      raise c.ConfigError(f"config.seeds[{i}] = {seed!r}: must be an integer in [0, "
                          f"{2**31 - 1}]")
  c.check_sequence(config, "strategies", item_choices=NAMES, distinct=True)
  c.check_int(config, "initial_view")
  max_views = c.check_int(config, "max_views", minimum=1)
  eval_views = c.check_sequence(config, "eval_views", item_minimum=1, distinct=True)
  if max(eval_views) > max_views:
    raise c.ConfigError(f"config.eval_views = {tuple(eval_views)!r}: every count must be <= "
                        f"config.max_views = {max_views}")
  c.check_bool(config, "progress")
  c.check_sequence(config, "paired_references", item_choices=NAMES, min_length=0,
                   distinct=True)

  data = data_spec(config.data)
  if data.kind not in FILE_KINDS:  # the size of a pool on disk is known once loaded
    if max_views > data.num_train:
      raise c.ConfigError(f"config.max_views = {max_views} must be <= config.data."
                          f"num_train = {data.num_train} (the candidates: selection "
                          "strategies pick distinct ones)")
    if config.initial_view >= data.num_train:
      raise c.ConfigError(f"config.initial_view = {config.initial_view} must be < config."
                          f"data.num_train = {data.num_train} (or < 0: a random one)")

  c.check_bool(config, "rounds.warm_start")
  c.check_int(config, "rounds.first_steps", minimum=1)
  c.check_int(config, "rounds.steps", minimum=1)
  c.check_int(config, "rounds.downscale", minimum=1)
  validate_training(config.round_train, prefix="config.round_train")
  validate_training(config.final_train, prefix="config.final_train")
  for name in ("round_train", "final_train"):
    if config[name].data.extent is None:
      raise c.ConfigError(f"config.{name}.data.extent = None: the planning protocol needs a "
                          "fixed scene extent (the step's settings may not change with the "
                          "number of views)")
  if config.rounds.warm_start:
    # Warm start continues one padded state, which cannot change shape (runner.round_config).
    total = int(config.rounds.first_steps) + (max_views - 2) * int(config.rounds.steps)
    if config.round_train.densify.start < total:
      raise c.ConfigError(
          f"config.rounds.warm_start = True continues one fixed-shape model over {total} "
          f"steps, which cannot densify: config.round_train.densify.start = "
          f"{config.round_train.densify.start} must be >= {total}")

  c.check_int(config, "strategy.score_downscale", minimum=1)
  strategy_settings(config)

  c.check_choice(config, "eval.lpips_net", LPIPS_NETS)
  c.check_bool(config, "figures.enabled")
  c.check_int(config, "figures.landscape_u", minimum=1)
  c.check_int(config, "figures.landscape_v", minimum=1)
  c.check_bool(config, "figures.landscape_trajectory")
  if data.kind not in FILE_KINDS:  # the pool's image size is the config's
    check_image_size(config, data.width, data.height)
  return config


# The fields that render candidates smaller than the pool's images (`downscale_camera`).
SCORE_DOWNSCALES = ("strategy.score_downscale", "strategy.ours.score_downscale",
                    "strategy.fisher.score_downscale", "strategy.activenerf.score_downscale",
                    "strategy.optimize.downscale")


def check_image_size(config, width, height, pool=None, prefix="config"):
  """The rules of a planning config against its pool's images of `width` x `height` pixels,
  the config's (`pool` None) or those of the files at `pool`: the round models' images are
  box-filtered by `rounds.downscale` (which must divide both sides), the candidates scored
  at 1 / `SCORE_DOWNSCALES` of their size (at least one pixel). `validate` calls it where
  the config gives the size, the job once the pool is loaded; both before anything trains.

  Raises:
    ConfigError: naming the field, its value and the image size.
  """
  size = (f"the pool's images are {width} x {height} pixels ("
          + ("config.data.width x height)" if pool is None else f"the dataset at {pool})"))
  down = int(config.rounds.downscale)
  if width % down or height % down:
    raise config_checks.ConfigError(
        f"{prefix}.rounds.downscale = {down}: {size}, which it must divide (the round models' "
        "images are box-filtered by it)")
  for field in SCORE_DOWNSCALES:
    value = int(config_checks.get_field(config, field))
    if value > min(width, height):
      raise config_checks.ConfigError(
          f"{prefix}.{field} = {value}: {size}, which cannot be rendered {value} times smaller "
          f"(under one pixel); it must be <= {min(width, height)}")


# ----------------------------------------------------------------- variants


def lego(config):
  """NeRF Synthetic lego on a fixed pool, at 80 x 80 (rounds and scoring at 40 x 40)."""
  config.strategies = tuple(n for n in TABLE1_NAMES if not STRATEGIES[n].make(
      st.StrategySettings()).new_poses)  # the selection strategies: no oracle on disk
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
  config.data.kind = "synthetic"
  config.data.width = 24
  config.data.height = 24
  config.data.num_train = 8  # candidates
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


def get_config(variant=""):
  """`default_config()` with the comma-separated `variant` names applied (`VARIANTS`)."""
  return config_checks.with_variants(default_config(), variant, VARIANTS,
                                     "configs/camera_planning.py")


# ----------------------------------------------------------------- translators


def strategy_settings(config):
  """The `strategies.StrategySettings` of a planning config's `strategy` block."""
  s = config.strategy
  return st.StrategySettings(
      ours=from_block(st.OursSettings, s.ours, "config.strategy.ours"),
      optimize=from_block(st.AscentSettings, s.optimize, "config.strategy.optimize"),
      fisher=from_block(st.FisherSettings, s.fisher, "config.strategy.fisher"),
      activenerf=from_block(st.ActiveNerfSettings, s.activenerf, "config.strategy.activenerf"),
      acp=from_block(st.AcpSettings, s.acp, "config.strategy.acp"))
