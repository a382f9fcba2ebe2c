"""Fresh seeds 16-23 for farthest point, Ours (Sel.) and Ours (Opt. Best), pre-registered.

Ours (Opt. Best) was conceived after Ours (Opt. Sel.) had trailed Ours (Sel.) at 10 views
on seeds 0-15, and judged on those same seeds. This config tests it, and the still open
"Ours (Sel.) above farthest point" (+0.10 +- 0.06 dB over seeds 0-15), on seeds none of
these strategies has seen. It was committed before any of its runs. Fixed in advance:

- seeds 16-23, all eight reported, whatever they show (runs go seed by seed, so a call
  stopped early leaves seeds 16..k; the next call finishes them);
- the protocol of `camera_planning_rounds2000.py` unchanged (2000-step rounds, 600-step
  final models, 64 x 64 test views);
- the outcomes: at 10 views, PSNR paired by seed, mean +- standard error and the count
  of seeds where the first is better, of Ours (Opt. Best) - Ours (Sel.), Ours (Sel.) -
  farthest point and Ours (Opt. Best) - farthest point; the same at 5 views; then the
  same gaps pooled over seeds 0-23 (`camera_planning_rounds2000_seeds24.py`, a reload of
  the finished runs).

Ours (Opt. Sel.) and FisherRF are left out for time (each adds about 40 minutes on two
CPU cores). Run in the workdir of `camera_planning_rounds2000.py`:

  python experiments/camera_planning.py --config=configs/camera_planning_rounds2000_fresh.py \
      --workdir=workdirs/camera_planning_rounds2000
"""

from configs import camera_planning_rounds2000


def get_config():
  config = camera_planning_rounds2000.get_config()
  config.seeds = tuple(range(16, 24))
  config.strategies = ("farthest", "ours_sel", "ours_opt_best")
  config.paired_references = ("farthest", "ours_sel")
  return config
