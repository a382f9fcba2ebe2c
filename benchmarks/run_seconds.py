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

from mfsample.planning import runner

_RESULTS = flags.DEFINE_string(
    "results", "results/camera_planning_rounds2000_best/results.json", "results.json of the run.")
_SEEDS = flags.DEFINE_list("seeds", [], "Seed ranges a:b (seeds a .. b-1); default: all seeds.")
_STRATEGIES = flags.DEFINE_list("strategies", [], "Strategies (default: all of the run's).")


def seed_range(text):
  """'a:b' -> range(a, b), with a clear error for anything else."""
  try:
    first, end = (int(part) for part in text.split(":"))
  except ValueError:
    raise ValueError(f"a seed range is 'a:b' (seeds a .. b-1), got {text!r}") from None
  if end <= first:
    raise ValueError(f"seed range {text!r} is empty")
  return range(first, end)


def tables(records, ranges, names=()):
  """Markdown: one `runner.seconds_markdown` table per seed range (of the runs it holds)."""
  labels = {r["strategy"]: r["label"] for r in records}  # As the runner labels its tables.
  out = []
  for seeds in ranges:
    chosen = [r for r in records if r["seed"] in seeds and (not names or r["strategy"] in names)]
    title = (f"Seed {seeds.start}" if len(seeds) == 1
             else f"Seeds {seeds.start}-{seeds.stop - 1}")
    if not chosen:
      out.append(f"{title}: no runs.\n")
      continue
    out.append(f"{title}:\n\n" + runner.seconds_markdown(runner.seconds_summary(chosen), labels))
  return "\n".join(out)


def main(argv):
  del argv
  with open(_RESULTS.value) as f:
    records = json.load(f)["runs"]
  seeds = sorted({r["seed"] for r in records})
  ranges = ([seed_range(t) for t in _SEEDS.value] if _SEEDS.value
            else [range(seeds[0], seeds[-1] + 1)])
  print(tables(records, ranges, tuple(_STRATEGIES.value)))


if __name__ == "__main__":
  app.run(main)
