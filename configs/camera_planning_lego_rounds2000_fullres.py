"""Lego with round models and scoring at the test resolution, pre-registered.

On lego with 2000-step rounds Ours (Sel.) is level with farthest point at 10 views, with
plain round models (+0.03 +- 0.03 dB over sixteen seeds) and with the authors' round models
(-0.05 +- 0.05 over eight), where the paper reports +1.2 dB. Every lego config so far
trains the round models, and scores the candidates, at half the test resolution (40 x 40
for 80 x 80 test images), while the authors' rounds and scoring run at the full resolution
of their images. This config asks whether the 10-view gap moves when the round models see
the images at the size the final models are judged at. It was committed before any of its
runs. Fixed in advance:

- the protocol of `camera_planning_lego_rounds2000.py` (candidates = the 100 training views,
  test = 50 test views at 80 x 80, 2000-step plain round models with the volume term
  stopped for their last 100 steps, U with M = 8, 600-step final models) with one change:
  rounds and candidate scoring at 80 x 80 (`rounds.downscale` = `score_downscale` = 1);
- seeds 0-7, all eight reported, whatever they show; farthest point and Ours (Sel.);
- the outcomes: at 10 views, PSNR paired by seed, mean +- standard error and the count of
  seeds where Ours (Sel.) is better, of Ours (Sel.) - farthest point; the same at 5 views;
  and, per seed at 10 views, Ours (Sel.) here minus Ours (Sel.) of
  `results/camera_planning_lego_rounds2000/` (same seeds, rounds at 40 x 40).

Before this config was written, a pilot (`benchmarks/round_model_pilot.py` on the first
1 and 5 views of farthest point's seed-0 run, the config's Sobol seed) timed one round and
checked U, no planning run and no PSNR: at 80 x 80, 44 and 40 s per round (compilation
included) and rho(U, angle to the nearest training view) +0.96 and +0.58 over the other
candidates; at 40 x 40, 28 and 23 s and +0.91 and +0.54. The 80 x 80 figures come from

  PYTHONPATH=. python benchmarks/round_model_pilot.py \
      --config=configs/camera_planning_lego_rounds2000.py --config.rounds.downscale=1 \
      --config.strategy.score_downscale=1 \
      --results=results/camera_planning_lego_rounds2000/results.json --views=1,5

(run as two calls, --views=5 and --views=1, each timing its round alone), the 40 x 40 ones
from the same command without the two overrides.

A new protocol, so a workdir of its own. Farthest point trains no round model (its views
are those of every lego run) and reruns here only for its final models, so that the
pairing is checked rather than assumed:

  python experiments/camera_planning.py \
      --config=configs/camera_planning_lego_rounds2000_fullres.py \
      --workdir=workdirs/camera_planning_lego_rounds2000_fullres
"""

from configs import camera_planning_lego_rounds2000


def get_config():
  config = camera_planning_lego_rounds2000.get_config()
  config.rounds.downscale = 1  # Round models train on the 80 x 80 images ...
  config.strategy.score_downscale = 1  # ... and candidates are scored at 80 x 80.
  return config
