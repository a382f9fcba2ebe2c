"""Active illumination planning: every light strategy, one training run each, figures.

  python experiments/light_planning.py --config=configs/light_planning.py \
      --workdir=workdirs/light_planning

Writes results.json, table.md, metrics.png, relit.png and u_sphere.png to the workdir.
Running again on the same workdir resumes: finished strategies are loaded, an interrupted
one restarts at its last finished light.
"""

from absl import app, flags
from ml_collections import config_flags

from mfsample.lighting import run_light_planning

_CONFIG = config_flags.DEFINE_config_file("config", None, "Light-planning config file.",
                                          lock_config=True)
_WORKDIR = flags.DEFINE_string("workdir", None, "Output directory.")
flags.mark_flags_as_required(["config", "workdir"])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
  results = run_light_planning(_CONFIG.value, _WORKDIR.value)
  with open(f"{_WORKDIR.value}/table.md") as f:
    print(f.read())
  print(f"wall-clock of this call: {results['seconds_this_call']:.0f} s")


if __name__ == "__main__":
  app.run(main)
