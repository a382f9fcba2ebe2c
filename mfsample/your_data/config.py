"""The config of `run_next_views`: uncertainty maps and next views for a dataset or a .ply.

`default_config()` is a training config (`mfsample.train.config.default_config()`: the dataset, the
model, B_hat, the loss, the optimiser, densification and the render budget, each field with
its comment there) with the job's defaults below, plus three blocks of its own: `posthoc`
(bring a trained 3DGS model), `views` (which views train, which are candidates) and
`next_views` (how candidates are scored). The default runs the built-in Mitsuba scene at
64 x 64: a field trained 2000 steps on every 4th of its 100 candidate views, the other 75
ranked by U (about 5 minutes of CPU time). `configs/next_views.py`
selects variants; any field is overridden on the command line, e.g.
`--config.data.kind=colmap --config.data.path=~/captures/garden --config.data.downscale=8`.
"""

import ml_collections

from mfsample import config_checks as checks
from mfsample.config_blocks import data_spec
from mfsample.data import resolve_path
from mfsample.data.datasets import FILE_KINDS, kinds_offering
from mfsample.samplers import STOCHASTIC_KINDS
from mfsample.train import config as training_variants
from mfsample.train.config import default_config as training_config
from mfsample.train.config import validate as validate_training


def default_config():
  """The uncertainty job's `ml_collections.ConfigDict` (see the comment on each field)."""
  config = training_config()

  # ----------------------------------------------------------------- training defaults
  # The built-in scene at the planning pool's size (its captures are shared with it).
  config.data.width = 64
  config.data.height = 64
  config.data.num_test = 40
  config.model.sh_degree = 1  # Three SH degree steps would need more than 2000 steps.
  config.model.init_points = 3_000  # Random initial points in the scene box.
  config.model.max_gaussians = 20_000
  config.train.num_steps = 2_000  # Joint training (no .ply): 3DGS's schedule compressed ...
  config.densify.stop = 1_500  # ... densifying from step 500 to 1500, and ...
  config.sampler.stochastic_until = None  # ... a sample rendered at every step (the paper).
  config.eval.lpips_net = ""  # Test PSNR / SSIM only ("vgg16": LPIPS too, slow on a CPU).
  config.eval.save_images = 8  # Test views whose render and U map are written as PNG.
  config.render.max_intersections = 1 << 15  # Initial budget (grown on overflow).

  # ----------------------------------------------------------------- a pretrained model
  config.posthoc = posthoc = ml_collections.ConfigDict()  # Bring a trained 3DGS model.
  # A 3DGS point_cloud.ply (relative: to the cwd). Set: B_hat is fitted with its Gaussians
  # frozen (mfsample.train.posthoc) instead of training a field; data.* must then be the
  # capture it was trained on. "": train a stochastic field jointly on the views.
  posthoc.ply = ""
  # Steps of the B_hat fit (the paper's loss with its volume term); each costs one training
  # step. train.num_steps is the joint training's length and is not used then.
  posthoc.steps = 1_000
  # A model whose mean renders the test views below this PSNR (dB) does not reproduce the
  # capture (another capture, another world, another data.background): the job warns and
  # records it in results.json ("warnings"). The 3DGS paper's models score 23-30 dB.
  posthoc.min_psnr = 20.0

  # ----------------------------------------------------------------- views
  config.views = views = ml_collections.ConfigDict()  # Which views train, which are candidates.
  # Train (or fit B_hat) on every n-th view of the dataset's training split, from the first;
  # the others are the "unused" candidates. 1: all (then use next_views.candidates="sphere").
  views.train_every = 4

  # ----------------------------------------------------------------- next views
  config.next_views = nv = ml_collections.ConfigDict()  # Ranking candidate views by U.
  # "unused": the training split's views left out by views.train_every (their images give
  # the rank correlation of U with the model's error there); "sphere": new poses on a
  # sphere around the scene, oriented by the training cameras (no images, U only).
  nv.candidates = "unused"
  nv.k = 5  # How many next views to propose (the top k by U).
  nv.samples = 8  # M of U for the ranking (the planning configs': 8; the paper's: 2).
  nv.z_seed = 6174  # Sobol scrambling seed of U's samples (authors' code: 6174).
  nv.score_downscale = 1  # Candidates are scored at 1 / this of the image size.
  nv.sphere_views = 100  # candidates "sphere": how many poses (a Fibonacci spiral).
  nv.figure = True  # Write next_views.png (candidates by U, top k, test U maps).
  return config


def validate(config):
  """Checks every field the job reads (before anything is written); `ConfigError` naming
  the field and its range."""
  validate_training(config)  # every training field (data, model, sampler, loss, ..., eval)
  checks.check_choice(config, "sampler.kind", STOCHASTIC_KINDS)
  checks.check_choice(config, "next_views.candidates", ("unused", "sphere"))
  for field in ("views.train_every", "next_views.k", "next_views.score_downscale",
                "next_views.sphere_views", "posthoc.steps", "train.num_steps"):
    checks.check_int(config, field, minimum=1)
  checks.check_int(config, "next_views.samples", minimum=2)  # one sample: U = 0
  checks.check_int(config, "eval.save_images", minimum=0)
  checks.check_float(config, "posthoc.min_psnr", minimum=0.0)
  data = data_spec(config.data)  # (checked by the training validator)
  if config.model.init_from == "points" and "points" not in data.offers and not \
      config.posthoc.ply:
    with_points = ", ".join(map(repr, kinds_offering("points")))
    raise checks.ConfigError(f"config.model.init_from = 'points' needs the sparse points of a "
                             f"capture ({with_points}), but config.data.kind = "
                             f"{data.kind!r}")
  if config.next_views.candidates == "unused" and config.views.train_every == 1:
    raise checks.ConfigError("config.views.train_every = 1 trains on every view and leaves no "
                             "unused candidate: set it > 1 or next_views.candidates = 'sphere'")
  if config.posthoc.ply:
    if not resolve_path(config.posthoc.ply).is_file():
      raise FileNotFoundError(f"config.posthoc.ply = {config.posthoc.ply!r}: no such file "
                              f"({resolve_path(config.posthoc.ply)})")
  if data.kind not in FILE_KINDS:  # the views' count and size are the config's
    check_views(config, data.num_train, data.width, data.height)


def check_views(config, num_train, width, height, dataset=None):
  """The rules of the views and candidates against the dataset's training views: `num_train`
  of `width` x `height` pixels, the config's (`dataset` None) or those of the files at
  `dataset`. `validate` calls it where the config gives them, the job once the data are
  loaded; both before anything is trained.

  Raises:
    ConfigError: no unused candidate would be left, or the candidates' scoring size would be
      under one pixel (naming the fields and the numbers).
  """
  every = int(config.views.train_every)
  train = -(-int(num_train) // every)  # views 0, every, 2 every, ...
  if config.next_views.candidates == "unused" and num_train - train < 1:
    count = (f"config.data.num_train = {num_train}" if dataset is None else
             f"the {num_train} training view(s) of the dataset at {dataset}")
    raise checks.ConfigError(
        f"{count} with config.views.train_every = {every} leaves no unused candidate view "
        f"({train} train): the dataset needs more than {train} view(s), or set "
        "next_views.candidates = 'sphere'")
  down = int(config.next_views.score_downscale)
  if down > min(width, height):
    size = ("config.data.width x height" if dataset is None else
            f"the images of the dataset at {dataset}")
    raise checks.ConfigError(
        f"config.next_views.score_downscale = {down}: the candidates are {width} x {height} "
        f"pixels ({size}) and cannot be scored {down} times smaller (under one pixel); it "
        f"must be <= {min(width, height)}")


# ----------------------------------------------------------------- variants


def colmap(config):
  """A COLMAP capture (Mip-NeRF 360 layout): images_8, every 8th image a test view."""
  config.data.kind = "colmap"
  config.data.path = "data/capture"  # Point --config.data.path at the scene folder.
  # images_8/: Mip-NeRF 360's smallest copies (a CPU's size); made from images/ when the
  # capture has none (mfsample.data.downscaled).
  config.data.downscale = 8
  config.data.background = (0.0, 0.0, 0.0)  # 3DGS's default for real captures.
  config.model.init_from = "points"  # 3DGS's start on real captures: the SfM points.


def posthoc(config):
  """A trained 3DGS model: B_hat fitted to its frozen Gaussians on every training view; the
  candidates are new poses on a sphere (no view is left unused)."""
  config.posthoc.ply = "point_cloud.ply"  # Point --config.posthoc.ply at the model.
  config.views.train_every = 1
  config.next_views.candidates = "sphere"


def tiny(config):
  """Random ground-truth Gaussians at 32 x 32: no files, no Mitsuba; about a minute on two
  CPU cores, nearly all of it compilation."""
  small = training_variants.get_config("tiny")
  for block in ("data", "model", "train", "densify", "loss", "render", "eval"):
    config[block] = small[block]
  config.data.num_train = 12
  config.densify.start = config.densify.stop = 1_000  # fixed shapes: one compilation
  config.eval.save_images = 2
  config.views.train_every = 2  # 6 training views, 6 candidates
  config.next_views.k = 2
  config.next_views.samples = 4
  config.next_views.sphere_views = 6
  config.posthoc.steps = 40  # (with posthoc: the B_hat fit as long as the training above)


VARIANTS = {f.__name__: f for f in (colmap, posthoc, tiny)}


def get_config(variant=""):
  """`default_config()` with the comma-separated `variant` names applied (`VARIANTS`)."""
  return checks.with_variants(default_config(), variant, VARIANTS,
                                "configs/next_views.py")
