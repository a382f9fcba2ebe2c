"""Lego with 2000-step rounds at sixteen seeds, pre-registered: is Ours (Sel.) above farthest?

`camera_planning_lego_rounds2000.py` left Ours (Sel.) level with farthest point at 10 views
(+0.04 +- 0.03 dB, 5 of 8 seeds). This config adds seeds 8-15 in the same workdir (it
reloads seeds 0-7) and was committed before any of their runs. Fixed in advance:

- the protocol of `camera_planning_lego_rounds2000.py` unchanged;
- seeds 8-15, all eight reported, whatever they show (runs go seed by seed; a call stopped
  early leaves seeds 8..k, and the next call finishes them);
- the outcomes: at 10 views, PSNR paired by seed, mean +- standard error and the count of
  seeds where Ours (Sel.) is better, of Ours (Sel.) - farthest point over seeds 8-15 and
  over all sixteen; the same at 5 views.

Farthest point's views need no round model; a seed took about 10 minutes on two CPU cores.

  python experiments/camera_planning.py \
      --config=configs/camera_planning_lego_rounds2000_seeds16.py \
      --workdir=workdirs/camera_planning_lego_rounds2000
"""

from configs import camera_planning_lego_rounds2000


def get_config():
  config = camera_planning_lego_rounds2000.get_config()
  config.seeds = tuple(range(16))
  return config
