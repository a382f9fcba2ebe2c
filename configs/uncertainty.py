"""Uncertainty maps and next views: `experiments/uncertainty.py --config=configs/uncertainty.py`.

Variants combine, comma-separated (the defaults and a comment on every field:
`mfsample.next_views.config`), e.g. `--config=configs/uncertainty.py:colmap,posthoc`:

  (none)   the built-in Mitsuba scene at 64 x 64: a field trained on every 4th of its 100
           candidate views (2000 steps), the other 75 ranked by U; about 5 minutes of CPU
           time.
  colmap   a COLMAP capture in the Mip-NeRF 360 layout at --config.data.path, its images_8,
           the 3DGS conventions (black background, Gaussians from the SfM points); with
           --config.data.kind=nerfstudio, an ns-process-data capture the same way.
  posthoc  a 3DGS model trained on every view (--config.posthoc.ply): B_hat fitted to it,
           candidates on a sphere around the scene.
  tiny     seconds-long: random ground-truth Gaussians at 32 x 32, 40 steps (tests).

docs/your_data.md has the commands.
"""

from mfsample.next_views.config import default_config


def get_config(variant=""):
  config = default_config()
  for name in filter(None, (v.strip() for v in variant.split(","))):
    if name not in VARIANTS:
      raise ValueError(f"unknown variant {name!r} of configs/uncertainty.py; known: "
                       f"{', '.join(VARIANTS)}")
    VARIANTS[name](config)
  return config


def colmap(config):
  """A COLMAP capture (Mip-NeRF 360 layout): images_8, every 8th image a test view."""
  config.data.kind = "colmap"
  config.data.path = "data/capture"  # Point --config.data.path at the scene folder.
  config.data.downscale = 8  # images_8/: Mip-NeRF 360's smallest copies (a CPU's size).
  config.data.background = (0.0, 0.0, 0.0)  # 3DGS's default for real captures.
  config.model.init_from = "points"  # 3DGS's start on real captures: the SfM points.


def posthoc(config):
  """A trained 3DGS model: B_hat fitted to its frozen Gaussians on every training view; the
  candidates are new poses on a sphere (no view is left unused)."""
  config.posthoc.ply = "point_cloud.ply"  # Point --config.posthoc.ply at the model.
  config.views.train_every = 1
  config.next_views.candidates = "sphere"


def tiny(config):
  """Random ground-truth Gaussians at 32 x 32: no files, no Mitsuba, a few seconds."""
  from configs.train import get_config as training_config

  small = training_config("tiny")
  for block in ("data", "model", "train", "densify", "loss", "render", "eval"):
    config[block] = small[block]
  config.data.synthetic.num_train = 12
  config.densify.start = config.densify.stop = 1_000  # fixed shapes: one compilation
  config.eval.save_images = 2
  config.views.train_every = 2  # 6 training views, 6 candidates
  config.next_views.k = 2
  config.next_views.samples = 4
  config.next_views.sphere_views = 6


VARIANTS = {f.__name__: f for f in (colmap, posthoc, tiny)}
