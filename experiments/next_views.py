"""Uncertainty maps of the test views and the next views to capture, for a dataset or a .ply.

  python experiments/next_views.py --config=configs/next_views.py --workdir=workdirs/unc
  python experiments/next_views.py --config=configs/next_views.py --workdir=workdirs/garden \
      --config.data.kind=colmap --config.data.path=~/captures/garden --config.data.downscale=8 \
      --config.posthoc.ply=~/models/garden/point_cloud.ply

Writes test/ (renders and U maps), next_views.json, next_views.png and results.json to the
workdir; running again on the same workdir resumes (docs/your_data.md).
"""

from mfsample import jobs
from mfsample.your_data.runner import JOB

if __name__ == "__main__":
  jobs.main(JOB)
