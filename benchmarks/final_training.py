"""Does the ranking of the planning strategies depend on how long the final model trains?

The planning protocol judges a view set by a plain model trained from scratch on it
(`config.final_train`; the authors: 7000 steps, the main job: 600). A model short of
convergence may blur, or reorder, the differences that view choice makes. This script
takes the views that a finished planning run chose (its `results.json`: candidate indices,
and the poses of the optimising variants, captured again by the scene's oracle), trains
the final model on them again for each number of steps in `--steps`, and evaluates it on
the same test views. Nothing but the final training length changes, so a row at the run's
own `final_steps` reproduces its table (a check that the re-run is the same protocol).

  PYTHONPATH=. python benchmarks/final_training.py \
      --results=results/camera_planning_default/results.json --steps=600,2000 --views=10

Prints PSNR / SSIM mean +- std over seeds per strategy and step count, and the per-seed
PSNR difference of every strategy to farthest-point sampling; writes `--out` (JSON).
"""

import json
import time

from absl import app, flags
from ml_collections import config_flags

_CONFIG = config_flags.DEFINE_config_file(
    "config", "configs/camera_planning.py", "The planning config of the run.",
    lock_config=False)
_RESULTS = flags.DEFINE_string(
    "results", "results/camera_planning_default/results.json", "results.json of the run.")
_STEPS = flags.DEFINE_list("steps", ["600", "2000"], "Final training lengths.")
_VIEWS = flags.DEFINE_list("views", ["10"], "View counts to evaluate (of the run's).")
_STRATEGIES = flags.DEFINE_list("strategies", [], "Strategies (default: all of the run's).")
_OUT = flags.DEFINE_string("out", "results/final_training.json", "JSON output.")


def _summary(rows, key):
  import numpy as np

  values = np.asarray([r[key] for r in rows], np.float64)
  return {"mean": float(values.mean()), "std": float(values.std()), "values": values.tolist()}


def main(argv):
  del argv
  import numpy as np
  from tqdm.auto import tqdm

  from mfsample.planning.pool import make_pool
  from mfsample.planning.runner import (
    Trainer,
    check_run_matches,
    evaluate_model,
    selected_from_record,
  )

  config = _CONFIG.value
  with open(_RESULTS.value) as f:
    results = json.load(f)
  wanted = set(_STRATEGIES.value) or set(results["strategies"])
  runs = [r for r in results["runs"] if r["strategy"] in wanted]
  views = [int(v) for v in _VIEWS.value]
  pool = make_pool(config.data)
  check_run_matches(pool, results)
  selections = [(run, selected_from_record(run, pool)) for run in runs]

  rows = []
  bar = tqdm(total=len(_STEPS.value) * len(runs) * len(views), desc="final models")
  for steps in (int(s) for s in _STEPS.value):
    cfg = config.copy_and_resolve_references()
    cfg.final_train.train.num_steps = steps
    cfg.final_train.train.log_every = steps
    trainer = Trainer(cfg, pool)
    settings = None
    for run, selected in selections:
      for n in views:
        t0 = time.perf_counter()
        model = trainer.final_model(selected[:n], int(run["seed"]))
        metrics, settings = evaluate_model(model, pool.test, background=pool.background,
                                           settings=settings or trainer.settings.get("final"))
        rows.append({"strategy": run["strategy"], "label": run["label"],
                     "seed": int(run["seed"]), "views": n, "steps": steps,
                     "psnr": metrics["psnr"], "ssim": metrics["ssim"],
                     "run_psnr": run["metrics"][str(n)]["psnr"],
                     "seconds": time.perf_counter() - t0})
        bar.update(1)
  bar.close()

  summary = {}
  for steps in (int(s) for s in _STEPS.value):
    for n in views:
      ref = {r["seed"]: r["psnr"] for r in rows
             if r["steps"] == steps and r["views"] == n and r["strategy"] == "farthest"}
      print(f"\n{n} views, {steps} final steps (run: {results['final_steps']}):")
      print("| Method | PSNR | SSIM | PSNR - farthest, per seed |\n|---|---|---|---|")
      for name in results["strategies"]:
        sel = [r for r in rows if r["steps"] == steps and r["views"] == n
               and r["strategy"] == name]
        if not sel:
          continue
        psnr, ssim = _summary(sel, "psnr"), _summary(sel, "ssim")
        diffs = [r["psnr"] - ref[r["seed"]] for r in sel if r["seed"] in ref]
        summary.setdefault(str(steps), {}).setdefault(str(n), {})[name] = {
            "psnr": psnr, "ssim": ssim, "psnr_minus_farthest": diffs}
        print(f"| {sel[0]['label']} | {psnr['mean']:.2f} ± {psnr['std']:.2f} | "
              f"{ssim['mean']:.3f} ± {ssim['std']:.3f} | "
              f"{', '.join(f'{d:+.2f}' for d in diffs)} |")
  reproduced = [abs(r["psnr"] - r["run_psnr"]) for r in rows
                if r["steps"] == int(results["final_steps"])]
  if reproduced:
    print(f"\nat the run's {results['final_steps']} steps the PSNRs reproduce the run's "
          f"within {max(reproduced):.3f} dB")
  out = {"results": _RESULTS.value, "final_steps_of_run": results["final_steps"],
         "steps": [int(s) for s in _STEPS.value], "views": views,
         "max_reproduction_error_db": max(reproduced) if reproduced else None,
         "summary": summary, "rows": rows, "seconds_per_model": {
             str(s): float(np.mean([r["seconds"] for r in rows if r["steps"] == int(s)]))
             for s in _STEPS.value}}
  from mfsample._json import write_json
  write_json(_OUT.value, out, indent=1)
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
