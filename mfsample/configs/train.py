"""Training a stochastic Gaussian field: `mfsample train --workdir=DIR [--config=VARIANT]`.

(From a clone: `python experiments/train.py --config=configs/train.py:VARIANT`.)

Variants (the defaults and a comment on every field: `mfsample.train.config`)::

  (none)  the built-in Mitsuba scene at 128 x 128, 7000 steps with densification.
  lego    NeRF Synthetic lego at 200 x 200 on white, all 100 training views, 5000 steps.
          Point `--config.data.path` at the scene folder (default data/nerf_synthetic/lego).
  tiny    random ground-truth Gaussians at 32 x 32, 40 steps (tests, smoke runs): 46 s of
          wall-clock on two CPU cores shared with other work (30 s of CPU time), nearly all
          of it compilation.

Any field is overridden on the command line, e.g. `--config.sampler.rank=4`.
"""

from mfsample.train.config import VARIANTS, get_config  # noqa: F401 (the variants live there)
