"""The uncertainty-quality experiment's config, with its defaults.

Two parts, each switched on by its `enabled` field:

* `ause` (the paper's Table 5): per scene a forward-facing arc of cameras captured with exact
  depth; models trained on every other view; on the views between, the AUSE of each
  method's per-pixel uncertainty against the depth error of its model.
* `candidates`: how well U ranks the unused candidate views of the planning pool by the round
  model's error there (Spearman's rho, `mfsample.planning.u_error`), over round lengths,
  samplers and M.

`default_config()` runs the AUSE part on the three built-in scenes at 64 x 64, one seed,
sized to finish within about 20 minutes on two CPU cores. `configs/uncertainty_quality.py`
selects variants (the candidates part, a tiny one for tests); every number is a field below.
"""

import math

import ml_collections

from mfsample import config_blocks as blocks
from mfsample import config_checks as cc
from mfsample.baselines.fisher import DEFAULT_GROUPS as FISHER_GROUPS
from mfsample.data import FILE_KINDS
from mfsample.data.datasets import kinds_offering
from mfsample.planning import config as planning_variants
from mfsample.planning.config import check_image_size
from mfsample.planning.config import default_config as planning_config
from mfsample.quality.benchmark import BASELINES, parse_sampler
from mfsample.train.config import default_config as training_config
from mfsample.train.config import validate as validate_training


def _training():
  """The models' training config: the planning rounds' recipe, at 64 x 64 for 1000 steps."""
  t = training_config()
  t.sampler.kind = "lowrank"  # Replaced per model (`ause.samplers`, "deterministic").
  t.sampler.rank = 2
  t.model.sh_degree = 0  # View-independent colour, as the planning rounds (short runs).
  t.model.init_points = 2_000  # Random initial points in the scene's bounding box (no SfM).
  t.model.max_gaussians = 8_000
  t.train.num_steps = 1_000  # Five 64 x 64 views: 200 passes over each.
  t.train.progress = False
  t.train.log_every = 1_000
  t.densify.start = 100_000  # No densification: one compilation per sampler, every scene.
  t.densify.stop = 100_000
  t.densify.opacity_reset_every = 100_000
  t.data.background = (1.0, 1.0, 1.0)  # The captures are composited on white.
  t.data.extent = 3.3  # The planning configs' scale for the same scenes (bounding radius 1).
  # lambda of the volume term: the planning rounds' value for short runs without
  # densification (there, U is then low near the training views and high away from them).
  t.loss.volume_weight = 1e-4
  t.loss.volume_stop_before_end = 50  # The authors' last 5% (100 of 2000 steps).
  t.render.max_intersections = 1 << 14  # Initial budget (grown on overflow).
  t.eval.lpips_net = ""
  return t


def default_config():
  """The uncertainty-quality `ml_collections.ConfigDict` (see the comment on each field)."""
  config = ml_collections.ConfigDict()
  config.progress = True  # tqdm progress bars.

  # ----------------------------------------------------------------- part 1: AUSE
  config.ause = a = ml_collections.ConfigDict()
  a.enabled = True  # Run the AUSE benchmark.
  a.scenes = ("tabletop", "still_life", "fence")  # mfsample.scenes names (data.kind "scene").
  a.seeds = (0,)  # Model seeds (initial points, B_hat signs, view order); one run each.
  # Samplers of the stochastic models, "kind" or "kind:k" (rank of lowrank and block): Ours
  # with rank 1, 2 (the paper's), 4, 10, and the paper's ablation covariances.
  a.samplers = ("lowrank:1", "lowrank:2", "lowrank:4", "lowrank:10", "diagonal", "block:2")
  # Baselines on a deterministic model: FisherRF's per-pixel uncertainty
  # (`baselines.fisher.fisher_pixel_variance`) and ActiveNeRF's rendered variance
  # (`baselines.activenerf.rendered_variance`). () trains no deterministic model.
  # "posthoc" (not by default): U of the same deterministic model after the fact, B_hat
  # fitted with its mean frozen (`mfsample.train.posthoc.fit_b_hat`), as for a pretrained
  # 3DGS model; its colour U and depth variance are scored as Ours'.
  a.baselines = ("fisher", "activenerf")
  a.posthoc_sampler = "lowrank:2"  # The fitted field's sampler, "kind" or "kind:k".
  # Steps of the B_hat fit (the deterministic model's training views; lambda = the models'
  # loss.volume_weight, else `posthoc.POSTHOC_VOLUME_WEIGHT`; learning rates the models').
  a.posthoc_steps = 400
  a.samples = 8  # M, samples of the stochastic maps (colour U and depth variance).
  a.z_seed = 6174  # Sobol scrambling seed of the low-rank samples (authors' code: 6174).

  # ----------------------------------------------------------------- data
  # A data kind with exact depth and coverage at any camera (mfsample.data.DATA_KINDS):
  # "scene" (Mitsuba captures) or "synthetic" (an opaque shell rendered by mfsample: tests),
  # at 64 x 64; ause.scenes names the built-in scenes (data.scene is replaced by each).
  config.data = data = blocks.data_block(
      width=64, height=64, spp=36,
      **{"synthetic.shape": "shell", "synthetic.num_gaussians": 150, "synthetic.radius": 0.5})
  # The forward-facing arc: num_views cameras at one height, looking at `target`, spread
  # evenly over `span_deg` of azimuth around `azimuth_deg`. Views 0, 2, ... (the 1st, 3rd,
  # ..., as in the light-field protocol) train the models; the views between them test.
  data.arc = arc = ml_collections.ConfigDict()
  arc.num_views = 9  # An odd number >= 3: (num_views + 1) / 2 train, the rest test.
  arc.azimuth_deg = -90.0  # Centre of the arc: from -y, looking towards +y.
  arc.span_deg = 80.0  # Azimuth from the first to the last camera.
  arc.polar_deg = 60.0  # Angle from +z (30 degrees above the table).
  arc.distance = 2.2  # From `target`: the table fills the frame.
  arc.target = (0.0, 0.0, -0.2)  # The centre of the table top (the scenes' TABLE = -0.3).
  arc.fov_deg = 40.0  # Horizontal field of view.

  # Where the depth error counts: pixels fully covered in the ground truth (every path
  # sample hit the scene: true alpha 1, up to float rounding) and by the model (alpha > 0.5).
  config.mask = mask = ml_collections.ConfigDict()
  mask.true_alpha_min = 0.999999  # Ground-truth coverage at least this.
  mask.model_alpha_min = 0.5  # The model's alpha above this.

  config.train = _training()  # The models (`mfsample.train` config); sampler set per model.

  config.fisher = fisher = ml_collections.ConfigDict()  # FisherRF (baselines.fisher).
  fisher.train_probes = 32  # Rademacher probes per training view for H(train) (a denominator).
  fisher.pixel_probes = 64  # Parameter probes per test view: relative noise <= sqrt(2 / 64).
  fisher.reg = 1e-6  # lambda of 1 / (H(train) + lambda) (FisherRF).
  fisher.groups = FISHER_GROUPS  # Parameter groups (FisherRF leaves out rotations).
  config.activenerf = an = ml_collections.ConfigDict()  # ActiveNeRF (baselines.activenerf).
  an.steps = 200  # Adam steps of the per-Gaussian log-variance fit (one view each).
  an.lr = 0.05  # Its learning rate.
  an.prior_var = 0.05  # Variance of Gaussians no view constrains.
  an.beta_min = 1e-3  # Variance floor of every pixel.
  an.prior_weight = 1e-3  # Weight of the quadratic prior on the log-variance.

  config.figures = fig = ml_collections.ConfigDict()
  fig.enabled = True  # Write uncertainty_quality_<scene>.png per scene.
  fig.test_view = 1  # Which test view the figure shows (0-based among the test views).

  # ----------------------------------------------------------------- part 2: candidates
  # U against the round model's error over the unused candidates of the planning pool
  # (`planning.u_error`): view sets of the farthest-point strategy cut at `views`; for every
  # round length, sampler and M, Spearman's rho; each setting paired with the first listed.
  config.candidates = c = ml_collections.ConfigDict()
  c.enabled = False  # Run this part (variant "candidates").
  c.planning = planning_config()  # The pool, round models and scoring (the main job's).
  c.steps = (150, 400, 600)  # Round lengths (planning rounds.steps).
  c.samplers = ("lowrank:2",)  # Round-model samplers, "kind" or "kind:k".
  c.samples = (2, 8)  # M of U.
  c.seeds = (0, 1)  # Seeds (initial view, model initialisation).
  c.views = (1, 3, 6, 9)  # Training-view counts (cuts of each seed's trajectory).
  return config


def validate(config):
  """Checks every field the experiment reads; `ConfigError` naming the field and its range."""
  a, d = config.ause, config.data
  if not (a.enabled or config.candidates.enabled):
    raise cc.ConfigError("config.ause.enabled and config.candidates.enabled are both "
                             "False: nothing to run")
  if a.enabled:
    spec = blocks.data_spec(config.data)
    if "depth" not in spec.offers:
      raise cc.ConfigError(f"config.data.kind = {spec.kind!r} has no exact depth at new "
                           f"cameras: must be one of "
                           f"{', '.join(map(repr, kinds_offering('depth')))}")
    if d.kind == "scene":
      from mfsample.scenes import SCENES
      cc.check_sequence(config, "ause.scenes", item_choices=SCENES, distinct=True)
    else:
      cc.check_sequence(config, "ause.scenes", distinct=True)
    cc.check_sequence(config, "ause.seeds", item_minimum=0, distinct=True)
    _check_samplers(config, "ause.samplers", min_length=0)
    cc.check_sequence(config, "ause.baselines", item_choices=BASELINES,
                          min_length=0, distinct=True)
    if not (a.samplers or a.baselines):
      raise cc.ConfigError("config.ause.samplers and config.ause.baselines are both "
                               "empty: no method to measure")
    _check_samplers(config, "ause.posthoc_sampler", min_length=1, single=True)
    cc.check_int(config, "ause.posthoc_steps", minimum=1)
    cc.check_int(config, "ause.samples", minimum=2)
    cc.check_int(config, "ause.z_seed", minimum=0)
    cc.check_int(config, "data.width", minimum=1)
    cc.check_int(config, "data.height", minimum=1)
    spp = cc.check_int(config, "data.spp", minimum=1)
    if math.isqrt(spp) ** 2 != spp:
      raise cc.ConfigError(f"config.data.spp = {spp}: must be a perfect square (the "
                               "stratified sampler's grid)")
    views = cc.check_int(config, "data.arc.num_views", minimum=3)
    if views % 2 == 0:
      raise cc.ConfigError(f"config.data.arc.num_views = {views}: must be odd (the "
                               "first and the last view train)")
    cc.check_float(config, "data.arc.span_deg", above=0.0, maximum=360.0)
    cc.check_float(config, "data.arc.polar_deg", above=0.0, below=180.0)
    cc.check_float(config, "data.arc.distance", above=0.0)
    cc.check_float(config, "data.arc.fov_deg", above=0.0, below=180.0)
    cc.check_float(config, "mask.true_alpha_min", above=0.0, maximum=1.0)
    cc.check_float(config, "mask.model_alpha_min", minimum=0.0, below=1.0)
    validate_training(config.train, prefix="config.train")
    steps = cc.check_int(config, "train.train.num_steps", minimum=1)
    if int(config.train.densify.start) < steps:
      raise cc.ConfigError(
          f"config.train.densify.start = {config.train.densify.start}: the models train "
          f"with fixed shapes; it must be >= config.train.train.num_steps ({steps})")
    cc.check_int(config, "fisher.train_probes", minimum=1)
    cc.check_int(config, "fisher.pixel_probes", minimum=1)
    cc.check_float(config, "fisher.reg", above=0.0)
    cc.check_int(config, "activenerf.steps", minimum=1)
    cc.check_float(config, "activenerf.lr", above=0.0)
    cc.check_float(config, "activenerf.prior_var", above=0.0)
    cc.check_float(config, "activenerf.beta_min", above=0.0)
    cc.check_float(config, "activenerf.prior_weight", minimum=0.0)
    cc.check_int(config, "figures.test_view", minimum=0, maximum=views // 2 - 1)
  if config.candidates.enabled:
    cc.check_sequence(config, "candidates.steps", item_minimum=1, distinct=True)
    _check_samplers(config, "candidates.samplers", min_length=1)
    cc.check_sequence(config, "candidates.samples", item_minimum=2, distinct=True)
    cc.check_sequence(config, "candidates.seeds", item_minimum=0, distinct=True)
    counts = cc.check_sequence(config, "candidates.views", item_minimum=1, distinct=True)
    planning = config.candidates.planning
    if planning.data.kind not in FILE_KINDS and max(counts) >= int(planning.data.num_train):
      raise cc.ConfigError(
          f"config.candidates.views = {tuple(counts)}: every count must leave unused "
          f"candidates (< candidates.planning.data.num_train = "
          f"{planning.data.num_train})")
    if planning.data.kind not in FILE_KINDS:
      check_image_size(planning, planning.data.width, planning.data.height,
                       prefix="config.candidates.planning")


def _check_samplers(config, field, min_length, single=False):
  """Sampler flags ("kind" or "kind:k"); `single`: one flag (a string field), not a sequence."""
  if single:
    flags = (cc.get_field(config, field),)
  else:
    flags = cc.check_sequence(config, field, min_length=min_length, distinct=True)
  for flag in flags:
    try:
      parse_sampler(flag)
    except ValueError as e:
      raise cc.ConfigError(f"config.{field}: {e}") from None


# ----------------------------------------------------------------- variants


def candidates(config):
  """The candidates part alone."""
  config.ause.enabled = False
  config.candidates.enabled = True


def lego(config):
  """The candidates part on lego's fixed pool (its 100 training views, rounds at 40 x 40)."""
  candidates(config)
  planning_variants.lego(config.candidates.planning)


def posthoc(config):
  """Ours, rank 2, trained jointly against post-hoc: B_hat fitted to the deterministic model
  with its mean frozen (`ause.posthoc_sampler`, `ause.posthoc_steps`); the protocol as the
  default otherwise."""
  config.ause.samplers = ("lowrank:2",)
  config.ause.baselines = ("posthoc",)


def tiny(config):
  """Both parts at a tiny size: random Gaussians at 24 x 24, the planning tiny rounds.

  The models train with the round config of `configs/camera_planning.py:tiny` (100 steps,
  3 views), so tests share one compilation of the training step with the planning tests.
  """
  planning = config.candidates.planning
  planning_variants.tiny(planning)
  config.ause.scenes = ("synthetic",)
  config.ause.samplers = ("lowrank:2",)
  config.ause.samples = 4
  d = config.data
  d.kind = "synthetic"
  d.width = d.height = 24
  d.arc.num_views = 5
  d.arc.target = (0.0, 0.0, 0.0)
  d.arc.distance = 3.0
  d.arc.polar_deg = 70.0
  config.mask.true_alpha_min = 0.9  # A shell of Gaussians is never exactly opaque.
  config.train = planning.round_train.copy_and_resolve_references()
  config.fisher.train_probes = 2
  config.fisher.pixel_probes = 4
  config.activenerf.steps = 4
  config.figures.test_view = 0
  config.candidates.enabled = True
  c = config.candidates
  c.steps = (int(planning.rounds.steps),)
  c.samplers = ("lowrank:2",)
  c.samples = (8, 2)  # M = 8 as the planning tiny variant scores (a shared compilation).
  c.seeds = (0,)
  c.views = (1, 2)


VARIANTS = {f.__name__: f for f in (candidates, lego, posthoc, tiny)}


def get_config(variant=""):
  """`default_config()` with the comma-separated `variant` names applied (`VARIANTS`)."""
  return cc.with_variants(default_config(), variant, VARIANTS,
                            "configs/uncertainty_quality.py")
