"""Training a stochastic Gaussian field (paper Sec. 4.3): loss, step, densification, loop.

The library (no configs, no files unless asked):

* `TrainSettings` (with `LossSettings`, `OptimSettings`, `DensifySettings`): frozen, every
  field defaulted.
* `fit(model, views, settings, *, key)` -> (model, history): the paper's training on any
  `Views`; `run_training` is the same with its whole record (state, budget, seconds) and
  optional checkpoints.
* `fit_b_hat`: B_hat fitted to a pretrained model's frozen mean (post-hoc uncertainty).
* the pieces of a custom loop: `make_setup`, `init_state`, `step_targets`, `train_step`
  (pure, jittable) / `make_train_step` (jitted), `with_grown_budget`, `host_events`.

The training job, `mfsample.train.experiment.train_and_evaluate(config, workdir)`, reads
its `ml_collections` config (`mfsample.train.config`) and calls these.
"""

from mfsample.train.loop import (
    TrainResult,
    TrainSetup,
    fit,
    host_events,
    init_state,
    make_setup,
    run_steps,
    run_training,
    step_targets,
    with_grown_budget,
)
from mfsample.train.posthoc import fit_b_hat, posthoc_settings
from mfsample.train.settings import (
    DensifySettings,
    InitSettings,
    LossSettings,
    OptimSettings,
    TrainSettings,
)
from mfsample.train.step import (
    DensifyStats,
    StepConfig,
    StepMetrics,
    TrainState,
    make_train_step,
    train_step,
)

__all__ = [
    "DensifySettings", "DensifyStats", "InitSettings", "LossSettings", "OptimSettings",
    "StepConfig", "StepMetrics", "TrainResult", "TrainSettings", "TrainSetup", "TrainState",
    "fit", "fit_b_hat", "host_events", "init_state", "make_setup", "make_train_step",
    "posthoc_settings", "run_steps", "run_training", "step_targets",
    "train_step", "with_grown_budget",
]
