"""Seeds 0-23 of farthest point, Ours (Sel.) and Ours (Opt. Best) at the paper's round length.

The pooled view of `camera_planning_rounds2000_best.py` (seeds 0-15) and the pre-registered
fresh seeds of `camera_planning_rounds2000_fresh.py` (16-23): once both have run, this call
runs nothing and only reloads the 72 runs to print the 24-seed table and paired gaps.

  python experiments/camera_planning.py --config=configs/camera_planning_rounds2000_seeds24.py \
      --workdir=workdirs/camera_planning_rounds2000
"""

from configs import camera_planning_rounds2000_fresh


def get_config():
  config = camera_planning_rounds2000_fresh.get_config()
  config.seeds = tuple(range(24))
  return config
