"""Uncertainty quality: AUSE against exact depth error, and U against the candidates' error.

  python experiments/uncertainty_quality.py --config=configs/uncertainty_quality.py \
      --workdir=workdirs/uncertainty_quality
  python experiments/uncertainty_quality.py --config=configs/uncertainty_quality.py:candidates \
      --workdir=workdirs/uncertainty_candidates

Writes table.md, results.json and (AUSE) uncertainty_quality_<scene>.png to the workdir.
Running again on the same workdir loads the finished units, so an interrupted call resumes,
and more seeds, scenes, samplers or cases can be added later.
"""

from absl import app, flags
from ml_collections import config_flags

from mfsample.quality import run_uncertainty_quality

_CONFIG = config_flags.DEFINE_config_file("config", None, "Uncertainty-quality config file.",
                                          lock_config=True)
_WORKDIR = flags.DEFINE_string("workdir", None, "Output directory.")
flags.mark_flags_as_required(["config", "workdir"])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
  results = run_uncertainty_quality(_CONFIG.value, _WORKDIR.value)
  with open(f"{_WORKDIR.value}/table.md") as f:
    print(f.read())
  print(f"wall-clock of this call: {results['seconds_this_call']:.0f} s")


if __name__ == "__main__":
  app.run(main)
