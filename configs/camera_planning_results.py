"""The Table 1-style results on the default scene: every strategy, three seeds.

Exactly the main job's protocol (`configs/camera_planning.py`) with seeds 0, 1 and 2, so
the main job's workdir already holds seed 0 and the results add the other two (about
three times the main job on two CPU cores; it resumes where it stopped):

  python experiments/camera_planning.py --config=configs/camera_planning_results.py \
      --workdir=workdirs/camera_planning
"""

from configs import camera_planning


def get_config():
  config = camera_planning.get_config()
  config.seeds = (0, 1, 2)
  return config
