"""Lego's selection comparison at eight seeds: farthest point, FisherRF, Ours (Sel.).

Exactly `configs/camera_planning_lego.py` with seeds 0-7, for the selection strategies
that the issue's aim compares at 10 views. Run in the lego workdir, it reuses seeds 0-2:

  python experiments/camera_planning.py --config=configs/camera_planning_lego_seeds8.py \
      --workdir=workdirs/camera_planning_lego
"""

from configs import camera_planning_lego


def get_config():
  config = camera_planning_lego.get_config()
  config.seeds = tuple(range(8))
  config.strategies = ("farthest", "fisher", "ours_sel")
  return config
