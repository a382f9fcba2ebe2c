"""The aim's comparison at eight seeds: farthest point, FisherRF, Ours (Sel.), Ours (Opt. Sel.).

Exactly the main job's protocol (`configs/camera_planning.py`) with seeds 0-7, for the
strategies that the issue's aim compares at 10 views. Three seeds leave the gaps between
them (0.1-0.2 dB) inside the seed-to-seed spread; eight narrow the standard error.
Run in the main job's workdir, it reuses seeds 0-2 of `camera_planning_results.py`:

  python experiments/camera_planning.py --config=configs/camera_planning_seeds8.py \
      --workdir=workdirs/camera_planning
"""

from configs import camera_planning


def get_config():
  config = camera_planning.get_config()
  config.seeds = tuple(range(8))
  config.strategies = ("farthest", "fisher", "ours_sel", "ours_opt_sel")
  return config
