"""Active camera planning: `mfsample camera-planning --workdir=DIR [--config=VARIANTS]`.

(From a clone: `python experiments/camera_planning.py --config=configs/camera_planning.py`.)

Without a variant this is the main job: every strategy of the paper's Table 1 on the
built-in Mitsuba scene, one seed, about 20 minutes on two CPU cores (the defaults and a
comment on every field: `mfsample.planning.config`). Variants combine, comma-separated,
e.g. `--config=lego,rounds2000` (`--config=configs/camera_planning.py:lego,rounds2000`)::

  lego             NeRF Synthetic lego at 80 x 80: candidates = its 100 training views,
                   test = every 4th test view; selection strategies only (no oracle).
                   Point `--config.data.path` at the scene folder.
  rounds2000       the paper's round length: 2000 steps per round instead of 400.
  authors_rounds   round models as the authors train them: densification, lambda = 1 / views.
  fullres          round models trained, and candidates scored, at the test resolution.
  densified_final  final models trained 2000 steps with 3DGS densification.
  paper_scale      lego's final models at the paper's scale (400 x 400, 100k points, 7000
                   densified steps; a GPU job), on round models at 40 x 40.
  tiny             random ground-truth Gaussians at 24 x 24, 3 views, every strategy: 2.5
                   minutes of wall-clock on two CPU cores shared with other work (80 s of
                   CPU time), nearly all of it compilation.

Seeds and strategies are overrides, e.g. `--config.seeds="(0,1,2,3,4,5,6,7)"
--config.strategies="('farthest','ours_sel')"`; docs/camera_planning.md lists each study.
"""

from mfsample.planning.config import VARIANTS, get_config  # noqa: F401 (the variants live there)
