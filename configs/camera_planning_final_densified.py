"""The default scene's view sets judged by densified final models, pre-registered.

The lego question of `camera_planning_lego_final_densified.py`, asked of the default scene,
where the aim's two comparisons stand on final models without densification: Ours (Sel.)
above farthest point at 10 views (+0.10 +- 0.04 dB with 600-step final models, +0.09 +-
0.06 with 2000-step ones), and the paper's Ours (Opt. Sel.) below Ours (Sel.) with 600-step
final models (-0.06 +- 0.03) but above it with 2000-step ones (+0.06 +- 0.05). A model
that densifies is the authors' final model; this is the sharpest judge the CPU affords. It
was committed before any of its models trained. Fixed in advance:

- the view sets: those of `results/camera_planning_rounds2000_opt_sel_seeds24/` (2000-step
  rounds), farthest point, Ours (Sel.) and Ours (Opt. Sel.), 10 views, one final model per
  view set (the run's seed);
- the final model: the protocol's (2000 random initial points, the run's images) trained
  2000 steps with densification every 100 steps from step 500 to the end, no opacity reset,
  at most 20 000 live Gaussians (the recipe of lego's densified judge);
- all 24 seeds, in two calls side by side (seeds 0-11 and 12-23, each to its own output,
  then merged by a third call over 0-24 with `--reuse_rows_from` that trains nothing); a
  call stopped early is resumed from its output, all 24 seeds reported, whatever they show;
- the outcomes: at 10 views, PSNR paired by seed, mean +- standard error and the count of
  seeds where the first is better, of Ours (Sel.) - farthest point and of Ours (Opt. Sel.) -
  Ours (Sel.), over seeds 0-23; beside them the same gaps with 2000-step final models
  without densification (`results/final_2000_rounds2000_opt_sel_seeds24.json`).

  PYTHONPATH=. python benchmarks/final_training.py \
      --config=configs/camera_planning_final_densified.py \
      --results=results/camera_planning_rounds2000_opt_sel_seeds24/results.json \
      --strategies=farthest,ours_sel,ours_opt_sel --seeds=0:12 --steps=2000 --views=10 \
      --references=farthest,ours_sel --out=OUT_A.json   # and --seeds=12:24 --out=OUT_B.json
  PYTHONPATH=. python benchmarks/final_training.py ... --seeds=0:24 \
      --out=results/final_2000_densified_default.json --reuse_rows_from=OUT_A.json,OUT_B.json

Added after the outcome over seeds 0-23 (Ours (Sel.) - farthest point -0.20 +- 0.11 dB,
10 of 24; Ours (Opt. Sel.) - Ours (Sel.) -0.18 +- 0.12, 8 of 24) and before any of its
models: how much of it is the densified model's own start. A second initialisation (train
seed + 1000) of all 72 view sets (`--inits=2`, the missing models in two calls side by side
over seeds 0-11 and 12-23, each with `--reuse_rows_from=results/final_2000_densified_default.json`,
then merged as above). The outcomes: the same two gaps of the per-view-set mean over the
two models, over seeds 0-23, whatever they show, beside the first initialisation alone and
the spread between a view set's two models. They were (docs/camera_planning.md): -0.23 +-
0.10 dB (10 of 24) and -0.18 +- 0.11 (8 of 24); a view set's two models differ by a median
0.21 dB.

The timing pilot that sized this (103 s a model alone) judged a view set outside the
outcome: FisherRF, seed 0, of `results/camera_planning_rounds2000/`.
"""

from configs import camera_planning_rounds2000_opt_sel_seeds24
from configs.camera_planning_lego_final_densified import with_densified_final_model


def get_config():
  return with_densified_final_model(camera_planning_rounds2000_opt_sel_seeds24.get_config())
