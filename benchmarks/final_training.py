"""Does the ranking of the planning strategies depend on the final model's training?

The planning protocol judges a view set by a plain model trained from scratch on it
(`config.final_train`; the authors: 7000 steps, the main job: 600), once, from the run's
seed. This script takes the views that a finished planning run chose (its `results.json`:
candidate indices, and the poses of the optimising variants, captured again by the scene's
oracle) and trains that final model again, changing only

- its length, for each number of steps in `--steps`: a model short of convergence may
  blur, or reorder, the differences that view choice makes;
- its initialisation, `--inits` of them per view set (seeds `seed + k * --init_offset`,
  k = 0, 1, ...): one final model measures its view set with the noise of its own random
  start, and that noise enters every paired difference between strategies. The mean over
  initialisations is a sharper measure of the views themselves; the spread between them
  is the noise floor of the single-model protocol.

Nothing else changes, so k = 0 at the run's own `final_steps` reproduces its table (a check
that the re-run is the same protocol; `--reuse_run` takes those rows from the record
instead of training them again). Rows are written as they finish; a later call on the
same `--out` resumes, and may add strategies, view counts, lengths or initialisations.
`--reuse_rows_from` takes rows from the output of a call on another run (say, the same
protocol with fewer seeds) wherever they are the model this call would train: the same
final training and train seed, on the same views.

  PYTHONPATH=. python benchmarks/final_training.py \
      --results=results/camera_planning_default/results.json --steps=600,2000 --views=10
  PYTHONPATH=. python benchmarks/final_training.py --config=configs/camera_planning_seeds8.py \
      --results=results/camera_planning_seeds8/results.json --steps=600 --views=5,10 \
      --inits=5 --reuse_run --out=results/final_inits_default.json

Prints PSNR / SSIM mean +- std over seeds per strategy and step count (of the mean over
initialisations), the paired PSNR differences, and the spread between initialisations;
writes `--out` (JSON).
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
_SEEDS = flags.DEFINE_string("seeds", "", "Seed range a:b of the run's seeds to judge "
                             "(seeds a .. b-1; default: all).")
_INITS = flags.DEFINE_integer("inits", 1, "Final models per view set, each from its own seed.")
_INIT_OFFSET = flags.DEFINE_integer(
    "init_offset", 1000, "Initialisation k trains from the run's seed + k * init_offset.")
_REUSE_RUN = flags.DEFINE_bool(
    "reuse_run", False, "Take initialisation 0 at the run's own final steps from the run's "
    "record instead of training it again.")
_REFERENCES = flags.DEFINE_list(
    "references", ["farthest", "fisher", "ours_sel"],
    "Strategies the others are paired with (those the run has).")
_ANY_RESOLUTION = flags.DEFINE_bool(
    "any_resolution", False, "Judge the run's views at the config's image size even where it "
    "differs from the run's (the same candidates by index; new poses captured at that size).")
_OUT = flags.DEFINE_string("out", "results/final_training.json", "JSON output (resumable).")
_REUSE_ROWS_FROM = flags.DEFINE_list(
    "reuse_rows_from", [], "Outputs of earlier calls (e.g. on a run with fewer seeds) whose "
    "rows are taken instead of trained again where they are the same model: the same final "
    "training, the same views (checked against their run's results.json) and train seed.")


def _models_to_train(runs, views, steps_list, train_seeds_of, reuse_at_steps):
  """(run, n, steps, train_seed, from the record?) of every final model, initialisation-major
  so that a run stopped early has the same initialisations for every view set. The first
  initialisation at `reuse_at_steps` (None: never) is read from the run's record."""
  for steps in steps_list:
    for k in range(_INITS.value):
      for run in runs:
        for n in views:
          yield run, n, steps, train_seeds_of(run)[k], k == 0 and steps == reuse_at_steps


def _per_view_set(rows, steps, n):
  """{(strategy, seed): [row per initialisation]} at one length and view count."""
  out = {}
  for r in rows:
    if r["steps"] == steps and r["views"] == n:
      out.setdefault((r["strategy"], r["seed"]), []).append(r)
  return out


def _report(results, rows, steps_list, views, inits):
  """Prints the tables; returns the summary for the JSON."""
  import numpy as np

  from mfsample.planning.tables import paired_differences, paired_markdown

  labels = {r["strategy"]: r["label"] for r in rows}
  references = [s for s in _REFERENCES.value if s in labels]
  summary = {}
  for steps in steps_list:
    for n in views:
      sets = _per_view_set(rows, steps, n)
      # A pseudo-run per view set whose metric is the mean over its initialisations, so the
      # planner's own paired statistics apply unchanged.
      records = [{"strategy": s, "seed": seed, "metrics": {str(n): {
          "psnr": float(np.mean([r["psnr"] for r in rs])),
          "ssim": float(np.mean([r["ssim"] for r in rs]))}}}
          for (s, seed), rs in sorted(sets.items(), key=lambda kv: kv[0][1])]
      # Spread of one final model around its view set's mean: the single-model noise.
      spread = [float(np.std([r["psnr"] for r in rs], ddof=1)) for rs in sets.values()
                if len(rs) > 1]
      entry = summary.setdefault(str(steps), {}).setdefault(str(n), {})
      print(f"\n{n} views, {steps} final steps (run: {results['final_steps']}), "
            f"PSNR and SSIM of the mean over {inits} initialisation(s):")
      print("| Method | PSNR | SSIM |\n|---|---|---|")
      for name in results["strategies"]:
        mine = [rec["metrics"][str(n)] for rec in records if rec["strategy"] == name]
        if not mine:
          continue
        psnr = np.asarray([m["psnr"] for m in mine])
        ssim = np.asarray([m["ssim"] for m in mine])
        entry.setdefault("strategies", {})[name] = {
            "psnr": {"mean": float(psnr.mean()), "std": float(psnr.std()),
                     "values": psnr.tolist()},
            "ssim": {"mean": float(ssim.mean()), "std": float(ssim.std())}}
        print(f"| {labels[name]} | {psnr.mean():.2f} ± {psnr.std():.2f} | "
              f"{ssim.mean():.3f} ± {ssim.std():.3f} |")
      if spread:
        entry["init_std_psnr"] = {"median": float(np.median(spread)),
                                  "mean": float(np.mean(spread)), "view_sets": len(spread)}
        print(f"\nstd of PSNR between the initialisations of one view set: median "
              f"{np.median(spread):.3f} dB, mean {np.mean(spread):.3f} over {len(spread)} "
              "view sets")
      # The same differences from the first initialisation alone (the run's own models).
      first = [{"strategy": s, "seed": seed, "metrics": {str(n): {"psnr": r["psnr"]}}}
               for (s, seed), rs in sorted(sets.items(), key=lambda kv: kv[0][1])
               for r in rs if r["train_seed"] == seed]
      for reference in references:
        paired = paired_differences(records, [n], reference)
        entry.setdefault("paired_psnr", {})[reference] = paired
        print(f"\npaired with {labels[reference]}, mean ± standard error, of the mean over "
              "the initialisations:\n")
        print(paired_markdown(paired, labels, labels[reference], [n]), end="")
        if inits > 1:
          alone = paired_differences(first, [n], reference)
          entry.setdefault("paired_psnr_first_init", {})[reference] = alone
          print("\nof the first initialisation alone (the protocol's one model):\n")
          print(paired_markdown(alone, labels, labels[reference], [n]), end="")
          noise = _difference_noise(sets, reference)
          entry.setdefault("paired_difference_init_std", {})[reference] = noise
          print("std between initialisations of one seed's difference (median over seeds): "
                + ", ".join(f"{labels[k]} {v:.3f} dB" for k, v in noise.items()))
  return summary


def _difference_noise(sets, reference):
  """{strategy: median over seeds of the std, across initialisations k, of PSNR(strategy, k)
  - PSNR(reference, k)}: the noise a paired difference of one final model each carries."""
  import numpy as np

  by_init = {key: {r["train_seed"]: r["psnr"] for r in rs} for key, rs in sets.items()}
  out = {}
  for (name, seed), mine in by_init.items():
    ref = by_init.get((reference, seed))
    if name == reference or ref is None:
      continue
    d = [mine[t] - ref[t] for t in mine if t in ref]
    if len(d) > 1:
      out.setdefault(name, []).append(float(np.std(d, ddof=1)))
  return {name: float(np.median(v)) for name, v in out.items()}


def main(argv):
  del argv
  import jax
  import numpy as np
  from tqdm.auto import tqdm

  from mfsample._json import read_resumable_rows, reusable_rows, write_json
  from mfsample.planning import by_seeds
  from mfsample.planning.pool import make_pool
  from mfsample.planning.runner import Trainer, evaluate_model, selected_from_record
  from mfsample.planning.workdirs import check_run_matches, pool_record
  from mfsample.train.loop import without_speed_only_fields

  if _INITS.value < 1:
    raise ValueError(f"--inits must be at least 1, not {_INITS.value}.")
  config = _CONFIG.value
  with open(_RESULTS.value) as f:
    results = json.load(f)
  wanted = set(_STRATEGIES.value) or set(results["strategies"])
  seeds = by_seeds.seed_range(_SEEDS.value) if _SEEDS.value else None
  runs = [r for r in results["runs"] if r["strategy"] in wanted
          and (seeds is None or int(r["seed"]) in seeds)]
  if not runs:
    raise ValueError(f"{_RESULTS.value} has no runs of {sorted(wanted)} in the seeds "
                     f"{_SEEDS.value or 'of the run'}")
  views = [int(v) for v in _VIEWS.value]
  steps_list = [int(s) for s in _STEPS.value]
  final_steps = int(results["final_steps"])
  pool = make_pool(config.data)
  check_run_matches(pool, results, any_resolution=_ANY_RESOLUTION.value)
  selections = {id(run): selected_from_record(run, pool) for run in runs}

  def train_seeds_of(run):
    return [int(run["seed"]) + k * _INIT_OFFSET.value for k in range(_INITS.value)]

  # What every row depends on besides its own keys; strategies, views, steps and the number
  # of initialisations may change between calls on one file (more rows of the same kind).
  header = {"results": _RESULTS.value,
            "config": config_flags.get_config_filename(flags.FLAGS["config"]),
            "final_train": without_speed_only_fields(
                json.loads(config.final_train.to_json_best_effort())),
            "init_offset": _INIT_OFFSET.value, "reuse_run": _REUSE_RUN.value}
  resolution = pool_record(pool)["resolution"]
  if resolution != results.get("resolution"):
    # Models of another image size than the run's: never the same rows as the run's size.
    header["judge_resolution"] = resolution
    if _REUSE_RUN.value:
      raise ValueError("--reuse_run takes the run's own models, which saw the run's image "
                       "size, not the config's.")
  rows = read_resumable_rows(_OUT.value, header)

  def key_of(model):
    run, n, steps, train_seed, _ = model
    return run["strategy"], int(run["seed"]), n, steps, train_seed

  def row_key(r):
    return r["strategy"], r["seed"], r["views"], r["steps"], r["train_seed"]

  reuse_at_steps = final_steps if _REUSE_RUN.value else None
  models = list(_models_to_train(runs, views, steps_list, train_seeds_of, reuse_at_steps))
  for path in _REUSE_ROWS_FROM.value:
    trained_here = {key_of(m) for m in models if not m[4]}
    done = {row_key(r) for r in rows}
    reused = reusable_rows(path, header, runs, trained_here - done)
    print(f"{len(reused)} rows reused from {path}")
    rows += reused
  if _REUSE_ROWS_FROM.value:
    write_json(_OUT.value, {"header": header, "rows": rows}, indent=1)
  done = {row_key(r) for r in rows}
  todo = [m for m in models if key_of(m) not in done]

  trainers, settings = {}, None
  for run, n, steps, train_seed, from_record in tqdm(todo, desc="final models"):
    row = {"strategy": run["strategy"], "label": run["label"], "seed": int(run["seed"]),
           "views": n, "steps": steps, "train_seed": train_seed,
           "run_psnr": run["metrics"][str(n)]["psnr"], "from_run_record": from_record}
    t0 = time.perf_counter()
    if from_record:
      metrics = run["metrics"][str(n)]
    else:
      if steps not in trainers:
        cfg = config.copy_and_resolve_references()
        cfg.final_train.train.num_steps = steps
        cfg.final_train.train.log_every = steps
        trainers[steps] = Trainer(cfg, pool)
      trainer = trainers[steps]
      model = trainer.final_model(selections[id(run)][:n], train_seed)
      metrics, settings = evaluate_model(model, pool.test, background=pool.background,
                                         settings=settings or trainer.settings.get("final"))
    row.update(psnr=float(metrics["psnr"]), ssim=float(metrics["ssim"]),
               seconds=time.perf_counter() - t0)
    if not from_record:  # the seconds are this device's (a judge may run on several)
      row["device"] = jax.devices()[0].device_kind
    rows.append(row)
    write_json(_OUT.value, {"header": header, "rows": rows}, indent=1)

  wanted_seeds = {(run["strategy"], int(run["seed"])): set(train_seeds_of(run)) for run in runs}
  rows_now = [r for r in rows if r["train_seed"] in wanted_seeds.get(
      (r["strategy"], r["seed"]), ())]
  summary = _report(results, rows_now, steps_list, views, _INITS.value)
  reproduced = [abs(r["psnr"] - r["run_psnr"]) for r in rows_now
                if r["steps"] == final_steps and r["train_seed"] == r["seed"]
                and not r["from_run_record"]]
  if reproduced:
    print(f"\nat the run's {final_steps} steps and seeds the PSNRs reproduce the run's "
          f"within {max(reproduced):.3f} dB")
  trained = [r for r in rows_now if not r["from_run_record"]]
  for steps in steps_list:
    for n in views:
      these = [r for r in trained if r["steps"] == steps and r["views"] == n]
      seconds = [r["seconds"] for r in these]
      reused = sum("reused_from" in r for r in these)
      if seconds:
        print(f"{n} views, {steps} steps: {len(seconds)} models trained"
              + (f" ({reused} of them by the call that wrote --reuse_rows_from)" if reused
                 else "")
              + f", {sum(seconds) / 60:.0f} min as recorded per row "
              f"({np.mean(seconds):.0f} s each)")
  # The models this file's own calls trained, i.e. the cost of --out beyond what it reused.
  own = [r["seconds"] for r in trained if "reused_from" not in r]
  if own:
    print(f"trained for {_OUT.value}: {len(own)} models, {sum(own) / 60:.0f} min as "
          f"recorded per row ({min(own):.0f}-{max(own):.0f} s each)")
  write_json(_OUT.value, {
      "header": header, "inits": _INITS.value, "rows": rows,
      "max_reproduction_error_db": max(reproduced) if reproduced else None,
      "summary": summary, "seconds_per_model": {
          str(s): float(np.mean([r["seconds"] for r in trained if r["steps"] == s]))
          for s in steps_list if any(r["steps"] == s for r in trained)}}, indent=1)
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
