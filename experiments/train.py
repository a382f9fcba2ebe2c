"""Trains a stochastic Gaussian field and evaluates it on the test views.

  python experiments/train.py --config=configs/train.py:lego --workdir=workdirs/lego \
      --config.data.path=/data/nerf_synthetic/lego --config.sampler.rank=4

Running again on the same workdir resumes from the newest intact checkpoint; a workdir made
with another config is refused (naming the fields), and nothing is written before the config
is validated (docs/reliability.md).
"""

from mfsample import jobs
from mfsample.train.experiment import JOB

if __name__ == "__main__":
  jobs.main(JOB)
