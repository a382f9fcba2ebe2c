"""The main job's comparison one step closer to the paper's scale: does the ranking move?

The default scene at 96 x 96 instead of 64 x 64 (rounds and scoring at 48 x 48), 600-step
rounds instead of 400 and 900 final steps instead of 600; everything else is the main job
(`configs/camera_planning.py`). Only the pair whose order the main job leaves open at 10
views, farthest point and Ours (Sel.), three seeds; about 2.5x the main job's cost per run.

  python experiments/camera_planning.py --config=configs/camera_planning_scale.py \
      --workdir=workdirs/camera_planning_scale
"""

from configs import camera_planning


def get_config():
  config = camera_planning.get_config()
  config.seeds = (0, 1, 2)
  config.strategies = ("farthest", "ours_sel")
  config.data.width = 96
  config.data.height = 96
  config.rounds.steps = 600
  config.round_train.loss.volume_stop_before_end = 15  # Same share of the round as 10 / 400.
  config.final_train.train.num_steps = 900
  config.final_train.train.log_every = 900
  for t in (config.round_train, config.final_train):
    t.render.max_intersections = 1 << 15  # 2.25x the pixels.
  return config
