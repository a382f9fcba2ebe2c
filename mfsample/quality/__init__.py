"""Uncertainty quality: AUSE against exact depth error (the paper's Table 5), and U against
the round model's error at the planning candidates.

* `config`: the experiment's config and its defaults (`default_config`).
* `arc`: the forward-facing views of the benchmark (exact depth from the capture oracle).
* `maps`: every method's per-pixel map, and the depth error they are judged against.
* `benchmark`: the AUSE protocol (train, map, score) and its resumable loop.
* `candidates`: Spearman's rho of U against the error over the unused candidates.
* `tables`, `figures`: the report.
* `runner`: `run_uncertainty_quality(config, workdir)`, both parts.

The metric itself is `mfsample.metrics.ause`.
"""

from mfsample.quality.config import default_config
from mfsample.quality.runner import run_uncertainty_quality

__all__ = ["default_config", "run_uncertainty_quality"]
