"""Ours (Opt. Best) at the paper's round length, sixteen seeds, beside the runs it extends.

`configs/camera_planning_rounds2000_seeds16.py` with Ours (Opt. Best) added: Ours (Opt.
Sel.) that keeps the highest-U pose among its start and the poses its ascent visited,
scored as Ours (Sel.) scores candidates (`strategies.ours_opt_best_strategy`). Its paired
gaps are to farthest point, Ours (Sel.) and Ours (Opt. Sel.). The seeds were fixed before
any of its runs; runs go seed by seed (0, 1, ...), so a call stopped early leaves seeds
0..k. Run in the workdir of `camera_planning_rounds2000.py`, it reuses the other three
strategies' 48 runs and runs Ours (Opt. Best) only:

  python experiments/camera_planning.py --config=configs/camera_planning_rounds2000_best.py \
      --workdir=workdirs/camera_planning_rounds2000
"""

from configs import camera_planning_rounds2000_seeds16


def get_config():
  config = camera_planning_rounds2000_seeds16.get_config()
  config.strategies = ("farthest", "ours_sel", "ours_opt_sel", "ours_opt_best")
  config.paired_references = ("farthest", "ours_sel", "ours_opt_sel")
  return config
