"""Training a stochastic Gaussian field (paper Sec. 4.3): loss, step, densification, loop.

The public entry points:

* `train(config, views)` -> `TrainResult`: train on any `Views` (planning reuses it).
* `train_and_evaluate(config, workdir)` -> `TrainState`: the experiment (data from the
  config, checkpoints, metrics, images, `.ply`).
* `make_setup`, `init_state`, `make_train_step`, `train_step`, `run_steps`: the pieces, for
  custom loops (the relightable field's training is one).
* `default_config()`: the training config with its defaults.
"""

from mfsample.train.config import default_config
from mfsample.train.experiment import train_and_evaluate
from mfsample.train.loop import (
                                 TrainResult,
                                 TrainSetup,
                                 init_state,
                                 make_setup,
                                 run_steps,
                                 train,
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
    "DensifyStats", "StepConfig", "StepMetrics", "TrainResult", "TrainSetup", "TrainState",
    "default_config", "init_state", "make_setup", "make_train_step", "run_steps", "train",
    "train_and_evaluate", "train_step",
]
