"""Wall-clock of a finished planning run's runs, per strategy, over ranges of seeds.

The runner's `table.md` ends with one wall-clock table over all seeds. When the seeds of a
workdir ran in different calls, or the machine was slower for some of them, a range of
seeds at a time says more. Reads `results.json` only (each run records its own `seconds`
and `round_seconds`; times include whatever else ran on the machine meanwhile).

  PYTHONPATH=. python benchmarks/run_seconds.py \
      --results=results/camera_planning_rounds2000_best/results.json --seeds=0:10,10:16

Prints, for each range `a:b` (seeds a .. b-1), the runner's table: runs, seconds per run
and seconds per round after the first (min / median / max).
"""

import json

from absl import app, flags

from mfsample.planning import by_seeds

_RESULTS = flags.DEFINE_string(
    "results", "results/camera_planning_rounds2000_best/results.json", "results.json of the run.")
_SEEDS = flags.DEFINE_list("seeds", [], "Seed ranges a:b (seeds a .. b-1); default: all seeds.")
_STRATEGIES = flags.DEFINE_list("strategies", [], "Strategies (default: all of the run's).")


def main(argv):
  del argv
  with open(_RESULTS.value) as f:
    records = json.load(f)["runs"]
  seeds = sorted({r["seed"] for r in records})
  ranges = ([by_seeds.seed_range(t) for t in _SEEDS.value] if _SEEDS.value
            else [range(seeds[0], seeds[-1] + 1)])
  print(by_seeds.seconds_tables(records, ranges, tuple(_STRATEGIES.value)))


if __name__ == "__main__":
  app.run(main)
