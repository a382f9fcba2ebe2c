"""Uncertainty quality: AUSE against exact depth error, and U against the candidates' error.

  python experiments/uncertainty_quality.py --config=configs/uncertainty_quality.py \
      --workdir=workdirs/uncertainty_quality
  python experiments/uncertainty_quality.py --config=configs/uncertainty_quality.py:candidates \
      --workdir=workdirs/uncertainty_candidates

Writes table.md, results.json and (AUSE) uncertainty_quality_<scene>.png to the workdir.
Running again on the same workdir loads the finished units, so an interrupted call resumes,
and more seeds, scenes, samplers or cases can be added later.
"""

from mfsample import jobs
from mfsample.quality.runner import JOB

if __name__ == "__main__":
  jobs.main(JOB)
