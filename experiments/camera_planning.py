"""Active camera planning: every strategy, rounds of training, final evaluation, figures.

  python experiments/camera_planning.py --config=configs/camera_planning.py \
      --workdir=workdirs/camera_planning

Writes results.json, table.md (paper Table 1 layout), cameras.png and landscape.png to the
workdir. Re-running with the same workdir skips the (strategy, seed) runs already done;
`--restore_from=results/<name>[,...]` first copies the finished runs of results directories
into the workdir (e.g. committed runs, on a machine that lacks their workdir), so only the
rest run.
"""

import sys
from pathlib import Path

from absl import app, flags
from ml_collections import config_flags

# The config files import each other as `configs.*`; configs/ is not an installed package.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mfsample.planning import restore_runs, run_camera_planning

_CONFIG = config_flags.DEFINE_config_file("config", None, "Planning config file.",
                                          lock_config=True)
_WORKDIR = flags.DEFINE_string("workdir", None, "Output directory.")
_RESTORE_FROM = flags.DEFINE_list(
    "restore_from", [],
    "Results directories (results.json + config.json) whose finished runs to copy into the "
    "workdir before running, in order; runs the workdir already has are kept.")
flags.mark_flags_as_required(["config", "workdir"])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
  for results_dir in _RESTORE_FROM.value:
    restored = restore_runs(results_dir, _WORKDIR.value)
    print(f"restored {len(restored)} run(s) from {results_dir}")
  results = run_camera_planning(_CONFIG.value, _WORKDIR.value)
  print(open(f"{_WORKDIR.value}/table.md").read())
  seconds = results["seconds"]
  print(f"wall-clock of this call: {seconds['total_this_call']:.0f} s; of all "
        f"{len(seconds['calls'])} call(s) on this workdir: "
        f"{sum(c['seconds'] for c in seconds['calls']):.0f} s")


if __name__ == "__main__":
  app.run(main)
