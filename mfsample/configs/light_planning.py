"""Active illumination planning: `mfsample light-planning --workdir=DIR [--config=VARIANTS]`.

(From a clone: `python experiments/light_planning.py --config=configs/light_planning.py`.)

Without a variant: every light strategy on the built-in Mitsuba scene, one seed, in about 20
minutes on two CPU cores (the defaults and a comment on every field:
`mfsample.lighting.config`). Variants::

  tiny   a synthetic diffuse shell of random Gaussians at 24 x 24, 3 lights, 15 steps per
         light: 21 s of wall-clock on two idle CPU cores (31 s of CPU time), nearly all of
         it compilation.

Any field is an override, e.g. `--config.steps_per_light=1000 --config.num_lights=6`.
"""

from mfsample.lighting.config import VARIANTS, get_config  # noqa: F401 (the variants live there)
