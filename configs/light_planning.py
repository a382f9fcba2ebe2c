"""Active illumination planning: `experiments/light_planning.py --config=configs/light_planning.py`.

Without a variant: every light strategy on the built-in Mitsuba scene, one seed, in about 20
minutes on two CPU cores (the defaults and a comment on every field:
`mfsample.lighting.config`). Variants:

  tiny   seconds-long: a synthetic diffuse shell of random Gaussians at 24 x 24, 3 lights.

Any field is an override, e.g. `--config.steps_per_light=1000 --config.num_lights=6`.
"""

from mfsample.lighting.config import default_config


def get_config(variant=""):
  config = default_config()
  for name in filter(None, (v.strip() for v in variant.split(","))):
    if name not in VARIANTS:
      raise ValueError(f"unknown variant {name!r} of configs/light_planning.py; known: "
                       f"{', '.join(VARIANTS)}")
    VARIANTS[name](config)
  return config


def tiny(config):
  """24 x 24 images of a synthetic diffuse shell (no Mitsuba), n = 4, 3 lights, few steps."""
  config.num_lights = 3
  config.steps_per_light = 30
  config.progress = False
  config.data.kind = "synthetic"
  config.data.width = 24
  config.data.height = 24
  config.data.num_train = 4
  config.data.num_test = 2
  config.data.progress = False
  config.model.out_coeffs = 1
  config.model.light_coeffs = 4
  config.model.init_points = 150
  config.model.max_gaussians = 512
  config.render.max_intersections = 1 << 11
  # Steps are few: T's rate 2x the default's (its B_hat keeps 0.1x of T's).
  config.optim.transfer_dc = 1e-2
  config.sampler.lr.transfer_dc = 1e-3
  config.loss.volume_every = 3
  config.planning.downscale = 1
  config.planning.ascent_steps = 6
  config.planning.ascent_lr = 0.3
  config.planning.ascent_final_lr = 0.03
  config.test_lights.num_environments = 2
  config.test_lights.num_random = 1
  config.eval.lpips_net = ""
  config.figures.sphere_height = 8
  config.figures.sphere_width = 16


VARIANTS = {f.__name__: f for f in (tiny,)}
