"""Does U follow the round model's error at the candidates? Round length, M and sampler.

Ours (Sel.) picks the candidate with the highest U (Eq. 10). That helps only if U ranks the
candidates as the current model's error there does: the paper's premise. This script
measures it on the planning pool of a config (default: the main job's, the built-in
default scene) for the round models that the protocol trains:

- view sets: the farthest-point trajectory of each seed (model-free, the same for every
  setting), cut at a few view counts;
- for every (round steps, sampler, M): the round model (`rounds.steps` steps,
  re-initialised, as in the protocol; the sampler `kind` or `lowrank:k` for rank k), U of
  every unused candidate at the scoring resolution, and the
  mean-squared error of the model's mean render against the candidate's image at the
  full resolution;
- Spearman's rho of U against that error, and against the angle to the nearest training
  view (coverage), over the unused candidates; mean over seeds and view counts.

  PYTHONPATH=. python benchmarks/uncertainty_error.py
  PYTHONPATH=. python benchmarks/uncertainty_error.py --steps=150,400,600 --samples=2,8

Every round length, sampler and M other than the first listed is paired with it, case by
case (printed and saved); `--summarize=OUT.json` prints them again from a saved output,
with each row's mean per seed.

  PYTHONPATH=. python benchmarks/uncertainty_error.py --steps=400 --samples=2,8 \
      --seeds=0,1,2,3,4,5,6,7 --samplers=lowrank:2,lowrank:1,lowrank:4,lowrank:10,diagonal,block \
      --out=results/uncertainty_error_samplers.json
"""

import itertools
import json
import time

from absl import app, flags
from ml_collections import config_flags

_CONFIG = config_flags.DEFINE_config_file(
    "config", "configs/camera_planning.py", "Planning config file.", lock_config=False)
_STEPS = flags.DEFINE_list("steps", ["150", "400", "600"], "Round lengths (rounds.steps).")
_SAMPLES = flags.DEFINE_list("samples", ["2", "8"], "M of U.")
_SAMPLERS = flags.DEFINE_list(
    "samplers", ["lowrank:2"], "Round-model samplers: a kind (lowrank, diagonal, block), "
    "with ':k' for the rank of lowrank and block (default: the config's). The others are "
    "paired with the first, case by case.")
_SEEDS = flags.DEFINE_list("seeds", ["0", "1"], "Seeds (initial view, model init).")
_VIEWS = flags.DEFINE_list("views", ["1", "3", "6", "9"], "Training-view counts.")
_OUT = flags.DEFINE_string("out", "results/uncertainty_error.json", "JSON output.")
_SUMMARIZE = flags.DEFINE_string(
    "summarize", None, "Only print each row's mean per seed and the paired differences of an "
    "earlier output (a JSON of this script), and stop; rows without a sampler (older "
    "outputs) are the config's rank-2 lowrank.")


# What a row varies; `_paired` pairs each with its first value, the others held equal.
_SETTINGS = ("round_steps", "sampler_flag", "samples")


def _farthest_views(pool, config, seed, num_views):
  """The farthest-point strategy's first `num_views` views from the seed's initial view."""
  from mfsample.planning import runner, strategies

  config = config.copy_and_resolve_references()
  config.max_views = num_views
  return runner.plan_views(strategies.make_strategy("farthest", config), pool, config, seed,
                           runner.Trainer(config, pool), budgets={})


def run():
  import numpy as np

  from mfsample import uncertainty as unc
  from mfsample.planning import runner
  from mfsample.planning.pool import make_pool
  from mfsample.planning.u_error import u_against_error

  config = _CONFIG.value
  config.data.progress = False
  pool = make_pool(config.data)
  cands = pool.candidates
  counts = [int(v) for v in _VIEWS.value]
  seeds = [int(s) for s in _SEEDS.value]

  trajectories = {seed: _farthest_views(pool, config, seed, max(counts)) for seed in seeds}
  rows = []
  for steps, sampler in itertools.product((int(s) for s in _STEPS.value), _SAMPLERS.value):
    kind, _, rank = sampler.partition(":")
    cfg = config.copy_and_resolve_references()
    cfg.rounds.steps = steps
    if rank:
      cfg.round_train.sampler.rank = int(rank)
    rank = int(cfg.round_train.sampler.rank)
    trainer = runner.Trainer(cfg, pool)
    settings = {}
    per_m = {int(m): [] for m in _SAMPLES.value}
    train_seconds = []
    for seed, n in itertools.product(seeds, counts):
      selected = trajectories[seed][:n]
      t0 = time.perf_counter()
      model = trainer.round_model(kind, selected, seed)
      train_seconds.append(time.perf_counter() - t0)
      for m in per_m:
        z = unc.uncertainty_z(model, m, int(cfg.strategy.ours.z_seed))
        res = u_against_error(model, cands, [view.index for view in selected], z,
                              background=pool.background, center=pool.sphere.center,
                              score_downscale=int(config.strategy.ours.score_downscale),
                              settings=settings)
        settings = res.settings
        per_m[m].append((res.rho_u_error, res.rho_u_angle, res.rho_error_angle))
    for m, values in per_m.items():
      values = np.asarray(values)
      row = {"round_steps": steps, "sampler": kind, "sampler_flag": sampler,
             "rank": rank if kind in ("lowrank", "block") else None, "samples": m,
             "rho_u_error": float(values[:, 0].mean()),
             "rho_u_angle": float(values[:, 1].mean()),
             "rho_error_angle": float(values[:, 2].mean()),
             "per_case_rho_u_error": values[:, 0].tolist(),
             "round_train_seconds_median": float(np.median(train_seconds))}
      rows.append(row)
      print(f"round steps {steps:4d}, {sampler}, M = {m:2d}: "
            f"rho(U, error) {row['rho_u_error']:.2f}, "
            f"rho(U, angle to views) {row['rho_u_angle']:.2f}, rho(error, angle) "
            f"{row['rho_error_angle']:.2f}; round training {row['round_train_seconds_median']:.1f}"
            " s", flush=True)
  return {"config": config_flags.get_config_filename(flags.FLAGS["config"]),
          "scene": pool.name, "seeds": seeds, "view_counts": counts,
          "cases_per_row": len(seeds) * len(counts), "rows": rows,
          "paired": [entry for field in _SETTINGS for entry in _paired(rows, field)]}


def _print_per_seed(rows, seeds):
  """rho(U, error) of every row, mean over each seed's view counts (cases are seed-major)."""
  import numpy as np

  print("rho(U, error) per seed " + " ".join(f"{s:>5}" for s in seeds))
  for r in rows:
    per_seed = np.asarray(r["per_case_rho_u_error"]).reshape(len(seeds), -1).mean(axis=1)
    print(f"{r['round_steps']:4d} steps, {r['sampler_flag']:>10}, M = {r['samples']:2d}: "
          + " ".join(f"{v:+.2f}" for v in per_seed))


def _paired(rows, field):
  """rho(U, error) of each value of `field` (round length, sampler or M) minus its first
  value in the rows, paired by case (the same seed and view set) with the other settings
  equal: mean, standard error and the cases above."""
  import numpy as np

  others = [f for f in _SETTINGS if f != field]
  first = rows[0][field]
  base = {tuple(r[f] for f in others): np.asarray(r["per_case_rho_u_error"])
          for r in rows if r[field] == first}
  paired = []
  for r in rows:
    if r[field] == first:
      continue
    diff = np.asarray(r["per_case_rho_u_error"]) - base[tuple(r[f] for f in others)]
    entry = {**{f: r[f] for f in _SETTINGS}, "minus": {field: first},
             "mean": float(diff.mean()),
             "sem": float(diff.std(ddof=1) / np.sqrt(len(diff))) if len(diff) > 1 else None,
             "cases_above": int(np.sum(diff > 0)), "cases": len(diff)}
    paired.append(entry)
    sem = "" if entry["sem"] is None else f" +- {entry['sem']:.2f}"
    where = ", ".join(f"{f} {r[f]}" for f in others)
    print(f"{where}: rho(U, error) of {field} {r[field]} - {first}: {entry['mean']:+.2f}{sem} "
          f"({entry['cases_above']}/{entry['cases']} cases above)")
  return paired


def main(argv):
  del argv
  if _SUMMARIZE.value:
    with open(_SUMMARIZE.value) as f:
      saved = json.load(f)
    rows = saved["rows"]
    for row in rows:  # outputs from before --samplers: the config's rank-2 lowrank
      row.setdefault("sampler_flag", "lowrank:2")
    _print_per_seed(rows, saved["seeds"])
    for field in _SETTINGS:
      _paired(rows, field)
    return
  from mfsample._json import write_json
  write_json(_OUT.value, run())
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
