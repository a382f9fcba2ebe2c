"""Uncertainty quality: `mfsample uncertainty-quality --workdir=DIR [--config=VARIANTS]`.

(From a clone: `python experiments/uncertainty_quality.py
--config=configs/uncertainty_quality.py`.)

Without a variant: the AUSE benchmark (the paper's Table 5) on the three built-in scenes,
64 x 64, one seed; the defaults and a comment on every field: `mfsample.quality.config`.
Variants combine, comma-separated::

  candidates  U against the round model's error at the planning candidates instead (the
              main job's pool; round lengths 150, 400, 600; M = 2 and 8; seeds 0 and 1).
  lego        with candidates: NeRF Synthetic lego's pool (the camera-planning `lego`;
              point `--config.candidates.planning.data.path` at the scene folder).
  posthoc     the jointly trained rank-2 field against B_hat fitted post hoc (400 steps) to
              the deterministic model of the same views and seed (`ause.baselines`).
  tiny        both parts at a tiny size: random ground-truth Gaussians at 24 x 24; 99 s of
              wall-clock on two CPU cores shared with other work (64 s of CPU time).

Everything else is an override, e.g. `--config.ause.samplers="('lowrank:2','diagonal')"`
or `--config.candidates.samplers="('lowrank:2','lowrank:10','diagonal')"`.
"""

from mfsample.quality.config import VARIANTS, get_config  # noqa: F401 (the variants live there)
