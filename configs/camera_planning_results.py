"""The Table 1-style results on the default scene: every strategy, three seeds, longer training.

Same protocol and scale as `configs/camera_planning.py` (64 x 64 images, 2000 initial
points), with 300 steps per round and 600 final steps, so that the final models reflect the
views more than their training noise. Takes a few hours on two busy CPU
cores; run it in the background (it resumes where it stopped):

  PYTHONPATH=. nohup python experiments/camera_planning.py \
      --config=configs/camera_planning_results.py --workdir=workdirs/camera_planning_results &
"""

from configs import camera_planning


def get_config():
  config = camera_planning.get_config()
  config.seeds = (0, 1, 2)
  config.rounds.steps = 300  # Per (re-initialised) round, at 32 x 32 (authors: 2000).
  config.final_train.train.num_steps = 600  # Authors: 7000.
  config.data.num_test = 50  # Held-out test views.
  config.data.progress = False
  return config
