"""Ours (Opt. Sel.) on the fresh seeds 16-23, pre-registered: is it below Ours (Sel.)?

At 10 views with 2000-step rounds the paper's Ours (Opt. Sel.) trailed Ours (Sel.) on
seeds 0-15 (-0.07 +- 0.04 dB, 5 of 16); `camera_planning_rounds2000_fresh.py` left it out
of seeds 16-23 for time. This config runs it there, beside the committed runs of
farthest point, Ours (Sel.) and Ours (Opt. Best) (seeds 0-15 from
`results/camera_planning_rounds2000_best`, 16-23 from `results/camera_planning_rounds2000_fresh`,
restored, not rerun). It was committed before any of its runs. Fixed in advance:

- the protocol of `camera_planning_rounds2000.py` unchanged;
- Ours (Opt. Sel.) at seeds 16-23, all eight reported, whatever they show (runs go seed by
  seed; a call stopped early leaves seeds 16..k, and the next call finishes them);
- the outcomes: at 10 views, PSNR paired by seed, mean +- standard error and the count of
  seeds where Ours (Opt. Sel.) is better, of Ours (Opt. Sel.) - Ours (Sel.) over seeds
  16-23 and over seeds 0-23; the same at 5 views.

  python experiments/camera_planning.py \
      --config=configs/camera_planning_rounds2000_opt_sel_seeds24.py \
      --workdir=workdirs/camera_planning_rounds2000_opt_sel_seeds24 \
      --restore_from=results/camera_planning_rounds2000_best,results/camera_planning_rounds2000_fresh
"""

from configs import camera_planning_rounds2000


def get_config():
  config = camera_planning_rounds2000.get_config()
  config.seeds = tuple(range(24))
  config.strategies = ("farthest", "ours_sel", "ours_opt_sel", "ours_opt_best")
  config.paired_references = ("farthest", "ours_sel")
  return config
