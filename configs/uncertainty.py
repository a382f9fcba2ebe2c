"""Uncertainty maps and next views: `experiments/uncertainty.py --config=configs/uncertainty.py`.

Variants (the defaults and a comment on every field: `mfsample.next_views.config`):

  (none)  the built-in Mitsuba scene at 64 x 64: a field trained on every 4th of its 100
          candidate views (2000 steps), the other 75 ranked by U; about 5 minutes on two
          CPU cores.
  tiny    seconds-long: random ground-truth Gaussians at 32 x 32, 40 steps (tests).

Your own data is a set of overrides, e.g. a COLMAP capture and a 3DGS model trained on it:

  --config.data.kind=colmap --config.data.path=~/captures/garden --config.data.downscale=8
  --config.model.init_from=points --config.posthoc.ply=~/models/garden/point_cloud.ply
  --config.views.train_every=1 --config.next_views.candidates=sphere

(docs/your_data.md).
"""

from mfsample.next_views.config import default_config


def get_config(variant=""):
  config = default_config()
  if variant == "tiny":
    _tiny(config)
  elif variant:
    raise ValueError(f"unknown variant {variant!r} of configs/uncertainty.py; known: tiny")
  return config


def _tiny(config):
  """Random ground-truth Gaussians at 32 x 32: no files, no Mitsuba, a few seconds."""
  from configs.train import get_config as training_config

  tiny = training_config("tiny")
  for block in ("data", "model", "train", "densify", "loss", "render", "eval"):
    config[block] = tiny[block]
  config.data.synthetic.num_train = 12
  config.eval.save_images = 2
  config.views.train_every = 2  # 6 training views, 6 candidates
  config.next_views.k = 2
  config.next_views.samples = 4
  config.next_views.sphere_views = 6
