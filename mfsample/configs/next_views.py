"""Uncertainty maps and next views: `mfsample next-views --workdir=DIR [--config=VARIANTS]`.

(From a clone: `python experiments/next_views.py --config=configs/next_views.py`.)

Variants combine, comma-separated (the defaults and a comment on every field:
`mfsample.your_data.config`), e.g. `--config=colmap,posthoc`
(`--config=configs/next_views.py:colmap,posthoc`)::

  (none)   the built-in Mitsuba scene at 64 x 64: a field trained on every 4th of its 100
           candidate views (2000 steps), the other 75 ranked by U; about 5 minutes of CPU
           time.
  colmap   a COLMAP capture in the Mip-NeRF 360 layout at --config.data.path, its images_8,
           the 3DGS conventions (black background, Gaussians from the SfM points); with
           --config.data.kind=nerfstudio, an ns-process-data capture the same way.
  posthoc  a 3DGS model trained on every view (--config.posthoc.ply): B_hat fitted to it,
           candidates on a sphere around the scene.
  tiny     random ground-truth Gaussians at 32 x 32, 40 steps (tests): 76 s of wall-clock on
           two CPU cores shared with other work (37 s of CPU time), nearly all compilation.

docs/your_data.md has the commands.
"""

from mfsample.your_data.config import VARIANTS, get_config  # noqa: F401 (the variants live there)
