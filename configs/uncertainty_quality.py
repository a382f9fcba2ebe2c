"""The uncertainty-quality experiment, `experiments/uncertainty_quality.py`.

Without a variant: the AUSE benchmark (the paper's Table 5) on the three built-in scenes,
64 x 64, one seed; the defaults and a comment on every field: `mfsample.quality.config`.
Variants combine, comma-separated:

  candidates  U against the round model's error at the planning candidates instead (the
              main job's pool; round lengths 150, 400, 600; M = 2 and 8; seeds 0 and 1).
  lego        with candidates: NeRF Synthetic lego's pool (`configs/camera_planning.py:lego`;
              point `--config.candidates.planning.data.path` at the scene folder).
  tiny        both parts at a tiny size: random ground-truth Gaussians at 24 x 24.

Everything else is an override, e.g. `--config.ause.samplers="('lowrank:2','diagonal')"`
or `--config.candidates.samplers="('lowrank:2','lowrank:10','diagonal')"`.
"""

from configs import camera_planning
from mfsample.quality.config import default_config


def get_config(variant=""):
  config = default_config()
  for name in filter(None, (v.strip() for v in variant.split(","))):
    if name not in VARIANTS:
      raise ValueError(f"unknown variant {name!r} of configs/uncertainty_quality.py; known: "
                       f"{', '.join(VARIANTS)}")
    VARIANTS[name](config)
  return config


def candidates(config):
  """The candidates part alone."""
  config.ause.enabled = False
  config.candidates.enabled = True


def lego(config):
  """The candidates part on lego's fixed pool (its 100 training views, rounds at 40 x 40)."""
  candidates(config)
  camera_planning.lego(config.candidates.planning)


def tiny(config):
  """Both parts at a tiny size: random Gaussians at 24 x 24, the planning tiny rounds.

  The models train with the round config of `configs/camera_planning.py:tiny` (100 steps,
  3 views), so tests share one compilation of the training step with the planning tests.
  """
  config.progress = False
  planning = config.candidates.planning
  camera_planning.tiny(planning)
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


VARIANTS = {f.__name__: f for f in (candidates, lego, tiny)}
