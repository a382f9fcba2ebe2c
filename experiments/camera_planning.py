"""Active camera planning: every strategy, rounds of training, final evaluation, figures.

  python experiments/camera_planning.py --config=configs/camera_planning.py \
      --workdir=workdirs/camera_planning

Writes results.json, table.md (the paper's Table 1 layout), cameras.png and landscape.png
to the workdir. Running again on the same workdir skips the (strategy, seed) runs already
done, so an interrupted call resumes, and more seeds or strategies can be added later; a
workdir whose runs used another protocol is refused, and nothing is written before the config
is validated (docs/reliability.md).
"""

from absl import app, flags
from ml_collections import config_flags

from mfsample.planning import run_camera_planning

_CONFIG = config_flags.DEFINE_config_file("config", None, "Planning config file.",
                                          lock_config=True)
_WORKDIR = flags.DEFINE_string("workdir", None, "Output directory.")
flags.mark_flags_as_required(["config", "workdir"])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
  results = run_camera_planning(_CONFIG.value, _WORKDIR.value)
  with open(f"{_WORKDIR.value}/table.md") as f:
    print(f.read())
  print(f"wall-clock of this call: {results['seconds_this_call']:.0f} s")


if __name__ == "__main__":
  app.run(main)
