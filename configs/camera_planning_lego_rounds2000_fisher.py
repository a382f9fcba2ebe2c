"""Lego with 2000-step rounds and FisherRF, pre-registered: is Ours (Sel.) above FisherRF?

On lego, Ours (Sel.) was above FisherRF only with 400-step rounds (+0.08 +- 0.05 dB at 10
views, 7 of 8 seeds); `camera_planning_lego_rounds2000.py` left FisherRF out for time. On
the default scene the 2000-step rounds kept Ours (Sel.) above FisherRF (+0.31 +- 0.10,
7 of 8). This config adds FisherRF to seeds 0-7 of the 2000-step lego runs and was
committed before any of its runs. Fixed in advance:

- the protocol of `camera_planning_lego_rounds2000.py` unchanged; farthest point and
  Ours (Sel.) are its committed runs, restored into the workdir, not rerun;
- seeds 0-7 of FisherRF, all eight reported, whatever they show (runs go seed by seed; a
  call stopped early leaves seeds 0..k, and the next call finishes them);
- the outcomes: at 10 views, PSNR paired by seed, mean +- standard error and the count of
  seeds where Ours (Sel.) is better, of Ours (Sel.) - FisherRF; the same at 5 views.
  Reported too, if there is time, as for the other 2000-step runs: the same outcomes with
  2000-step final models (`benchmarks/final_training.py --steps=2000`).

  python experiments/camera_planning.py \
      --config=configs/camera_planning_lego_rounds2000_fisher.py \
      --workdir=workdirs/camera_planning_lego_rounds2000_fisher \
      --restore_from=results/camera_planning_lego_rounds2000
"""

from configs import camera_planning_lego_rounds2000


def get_config():
  config = camera_planning_lego_rounds2000.get_config()
  config.strategies = ("farthest", "fisher", "ours_sel")
  config.paired_references = ("farthest", "fisher")
  return config
