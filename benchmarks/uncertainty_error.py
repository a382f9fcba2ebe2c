"""Does U follow the round model's error at the candidates? Round length and M against it.

Ours (Sel.) picks the candidate with the highest U (Eq. 10). That helps only if U ranks the
candidates as the current model's error there does: the paper's premise. This script
measures it on the planning pool of a config (default: the main job's, the built-in
default scene) for the round models that the protocol trains:

- view sets: the farthest-point trajectory of each seed (model-free, the same for every
  setting), cut at a few view counts;
- for every (round steps, M) pair: the round model (`rounds.steps` steps, re-initialised,
  as in the protocol), U of every unused candidate at the scoring resolution, and the
  mean-squared error of the model's mean render against the candidate's image at the
  full resolution;
- Spearman's rho of U against that error, and against the angle to the nearest training
  view (coverage), over the unused candidates; mean over seeds and view counts.

  PYTHONPATH=. python benchmarks/uncertainty_error.py
  PYTHONPATH=. python benchmarks/uncertainty_error.py --steps=150,400,600 --samples=2,8
"""

import itertools
import time

from absl import app, flags
from ml_collections import config_flags

_CONFIG = config_flags.DEFINE_config_file(
    "config", "configs/camera_planning.py", "Planning config file.", lock_config=False)
_STEPS = flags.DEFINE_list("steps", ["150", "400", "600"], "Round lengths (rounds.steps).")
_SAMPLES = flags.DEFINE_list("samples", ["2", "8"], "M of U.")
_SEEDS = flags.DEFINE_list("seeds", ["0", "1"], "Seeds (initial view, model init).")
_VIEWS = flags.DEFINE_list("views", ["1", "3", "6", "9"], "Training-view counts.")
_OUT = flags.DEFINE_string("out", "results/uncertainty_error.json", "JSON output.")


def _farthest_views(pool, config, seed, num_views):
  """The farthest-point strategy's first `num_views` views from the seed's initial view."""
  from mfsample.planning import runner, strategies

  config = config.copy_and_resolve_references()
  config.max_views = num_views
  return runner.plan_views(strategies.make_strategy("farthest", config), pool, config, seed,
                           runner.Trainer(config, pool), budgets={})


def run():
  import jax.numpy as jnp
  import numpy as np
  from scipy.stats import spearmanr

  from mfsample import uncertainty as unc
  from mfsample.planning import poses, runner
  from mfsample.planning.pool import make_pool
  from mfsample.render import RenderSettings
  from mfsample.render.budget import render_with_budget

  config = _CONFIG.value
  config.data.progress = False
  pool = make_pool(config.data)
  cands = pool.candidates
  bg = jnp.asarray(pool.background, jnp.float32)
  counts = [int(v) for v in _VIEWS.value]
  seeds = [int(s) for s in _SEEDS.value]
  small = poses.downscale_camera(cands.cameras, int(config.strategy.ours.score_downscale))

  trajectories = {seed: _farthest_views(pool, config, seed, max(counts)) for seed in seeds}
  rows = []
  for steps in (int(s) for s in _STEPS.value):
    cfg = config.copy_and_resolve_references()
    cfg.rounds.steps = steps
    trainer = runner.Trainer(cfg, pool)
    settings = {}
    per_m = {int(m): [] for m in _SAMPLES.value}
    train_seconds = []
    for seed, n in itertools.product(seeds, counts):
      selected = trajectories[seed][:n]
      idx = [view.index for view in selected]
      t0 = time.perf_counter()
      model = trainer.round_model("lowrank", selected, seed)
      train_seconds.append(time.perf_counter() - t0)
      (pred, _), settings["mean"] = render_with_budget(
          runner.render_views,
          settings.get("mean", RenderSettings(max_intersections=1 << 14)), model,
          cands.cameras, bg, stats_of=lambda out: out[1])
      error = np.mean((np.asarray(pred) - np.asarray(cands.images)) ** 2, axis=(1, 2, 3))
      unused = np.ones(len(cands), bool)
      unused[idx] = False
      angle = poses.angle_to_nearest(cands.cameras, idx, pool.sphere.center)[unused]
      for m in per_m:
        z = unc.uncertainty_z(model, m, int(cfg.strategy.ours.z_seed))
        out, settings["score"] = unc.score_cameras(
            model, small, z,
            settings=settings.get("score", RenderSettings(max_intersections=1 << 12)),
            background=bg, num_devices=1)
        u = np.asarray(out.values)[unused]
        per_m[m].append((spearmanr(u, error[unused]).correlation,
                         spearmanr(u, angle).correlation,
                         spearmanr(error[unused], angle).correlation))
    for m, values in per_m.items():
      values = np.asarray(values)
      row = {"round_steps": steps, "samples": m,
             "rho_u_error": float(values[:, 0].mean()),
             "rho_u_angle": float(values[:, 1].mean()),
             "rho_error_angle": float(values[:, 2].mean()),
             "per_case_rho_u_error": values[:, 0].tolist(),
             "round_train_seconds_median": float(np.median(train_seconds))}
      rows.append(row)
      print(f"round steps {steps:4d}, M = {m:2d}: rho(U, error) {row['rho_u_error']:.2f}, "
            f"rho(U, angle to views) {row['rho_u_angle']:.2f}, rho(error, angle) "
            f"{row['rho_error_angle']:.2f}; round training {row['round_train_seconds_median']:.1f}"
            " s", flush=True)
  return {"config": config_flags.get_config_filename(flags.FLAGS["config"]),
          "scene": pool.name, "seeds": seeds, "view_counts": counts,
          "cases_per_row": len(seeds) * len(counts), "rows": rows}


def main(argv):
  del argv
  from mfsample._json import write_json
  write_json(_OUT.value, run())
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
