"""Uncertainty maps and next views for your data: a capture, and optionally a trained .ply.

* `runner`: `run_next_views(config, workdir)`, the job of `experiments/next_views.py`.
* `config`: its config and defaults (`default_config`), and its validator.
* `candidates`: poses on a sphere oriented by the capture.
* `figure`: the job's figure.
* `export`: the proposals as files viewers open (cameras in their formats, previews).
* `uncertainty_ply`: the model with its uncertainty per Gaussian as 3DGS .ply files.
"""

from mfsample.your_data.candidates import sphere_candidates
from mfsample.your_data.config import default_config
from mfsample.your_data.runner import run_next_views

__all__ = ["default_config", "run_next_views", "sphere_candidates"]
