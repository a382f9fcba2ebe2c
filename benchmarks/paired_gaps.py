"""Paired gaps between strategies over ranges of seeds, from a planning run or its final models.

The runner's `table.md` pairs all the seeds of a run. A pre-registered call that adds seeds
to an earlier run names its outcomes over the new seeds and over all of them; this prints
the runner's paired table for each range `a:b` (seeds a .. b-1), from either

- a planning run's `results.json` (the metrics of the run's own final models), or
- the output of `benchmarks/final_training.py` (`--steps` picks the final models; of each
  view set, the model trained from the run's own seed, the protocol's one model; with
  `--mean_over_inits`, the mean over its initialisations).

  PYTHONPATH=. python benchmarks/paired_gaps.py \
      --results=results/camera_planning_lego_rounds2000_seeds16/results.json \
      --seeds=8:16,0:16 --references=farthest

`--compare=TAG:PATH` adds the runs of another results.json with the same seeds, renamed
`strategy@TAG`, so that one protocol pairs with another by seed; `--per_seed` lists each
seed's difference. E.g. Ours (Sel.) with the authors' round models minus Ours (Sel.) without
densification:

  PYTHONPATH=. python benchmarks/paired_gaps.py \
      --results=results/camera_planning_lego_rounds2000_authors/results.json \
      --compare=plain:results/camera_planning_lego_rounds2000/results.json \
      --references=ours_sel@plain --seeds=0:8 --per_seed
"""

import json

from absl import app, flags

from mfsample.planning import by_seeds

_RESULTS = flags.DEFINE_string(
    "results", None, "A run's results.json, or the JSON output of final_training.py.")
_SEEDS = flags.DEFINE_list("seeds", [], "Seed ranges a:b (seeds a .. b-1); default: all seeds.")
_REFERENCES = flags.DEFINE_list("references", ["farthest"], "Strategies to pair the others with.")
_VIEWS = flags.DEFINE_list("views", [], "View counts (default: all the file holds).")
_STEPS = flags.DEFINE_integer(
    "steps", None, "Final training length of the rows to use (final_training.py outputs only; "
    "needed when the file holds more than one).")
_COMPARE = flags.DEFINE_list(
    "compare", [], "TAG:PATH of other runs' results.json, paired by seed as strategy@TAG.")
_PER_SEED = flags.DEFINE_bool("per_seed", False, "Also list each seed's difference.")
_MEAN_OVER_INITS = flags.DEFINE_bool(
    "mean_over_inits", False, "final_training.py outputs: judge each view set by the mean over "
    "its initialisations instead of its one model from the run's own seed.")
_METRIC = flags.DEFINE_enum("metric", "psnr", ["psnr", "ssim", "lpips"], "Metric to pair.")


def _records(path):
  with open(path) as f:
    data = json.load(f)
  if "runs" in data:
    if _STEPS.value is not None:
      raise app.UsageError("--steps applies to final_training.py outputs, not to a run")
    if _MEAN_OVER_INITS.value:
      raise app.UsageError("--mean_over_inits applies to final_training.py outputs, not to a run")
    return data["runs"]
  if "rows" in data:
    return by_seeds.records_from_final_rows(data["rows"], _STEPS.value, _MEAN_OVER_INITS.value)
  raise ValueError(f"{path} holds neither a run's 'runs' nor final models' 'rows'")


def main(argv):
  del argv
  if _RESULTS.value is None:
    raise app.UsageError("--results is required")
  records = _records(_RESULTS.value)
  for entry in _COMPARE.value:
    tag, sep, path = entry.partition(":")
    if not sep or not path:
      raise app.UsageError(f"--compare takes TAG:PATH, got {entry!r}")
    records = records + by_seeds.tagged(_records(path), tag)
  held = sorted({int(n) for r in records for n in r["metrics"]})
  views = [int(v) for v in _VIEWS.value] or held
  missing = sorted(set(views) - set(held))
  if missing:
    raise ValueError(f"no metrics at {missing} views; the file holds {held}")
  strategies = {r["strategy"] for r in records}
  unknown = [s for s in _REFERENCES.value if s not in strategies]
  if unknown:
    raise ValueError(f"references {unknown} are not among the strategies of the file(s) "
                     f"{sorted(strategies)}")
  seeds = sorted({r["seed"] for r in records})
  ranges = ([by_seeds.seed_range(t) for t in _SEEDS.value] if _SEEDS.value
            else [range(seeds[0], seeds[-1] + 1)])
  print(by_seeds.paired_tables(records, ranges, _REFERENCES.value, views, _METRIC.value,
                              per_seed=_PER_SEED.value))


if __name__ == "__main__":
  app.run(main)
