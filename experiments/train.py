"""Trains a stochastic Gaussian field and evaluates it on the test views.

  python experiments/train.py --config=configs/train.py:lego --workdir=workdirs/lego \
      --config.data.path=/data/nerf_synthetic/lego --config.sampler.rank=4

Running again on the same workdir resumes from the newest intact checkpoint; a workdir made
with another config is refused (naming the fields), and nothing is written before the config
is validated (docs/reliability.md).
"""

from absl import app, flags
from ml_collections import config_flags

from mfsample.train import train_and_evaluate

_CONFIG = config_flags.DEFINE_config_file("config", None, "Training config file.",
                                          lock_config=True)
_WORKDIR = flags.DEFINE_string("workdir", None, "Output directory (checkpoints, metrics).")
flags.mark_flags_as_required(["config", "workdir"])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
  train_and_evaluate(_CONFIG.value, _WORKDIR.value)


if __name__ == "__main__":
  app.run(main)
