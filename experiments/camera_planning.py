"""Active camera planning: every strategy, rounds of training, final evaluation, figures.

  python experiments/camera_planning.py --config=configs/camera_planning.py \
      --workdir=workdirs/camera_planning

Writes results.json, table.md (the paper's Table 1 layout), cameras.png and landscape.png
to the workdir. Running again on the same workdir skips the (strategy, seed) runs already
done, so an interrupted call resumes, and more seeds or strategies can be added later; a
workdir whose runs used another protocol is refused, and nothing is written before the config
is validated (docs/reliability.md).
"""

from mfsample import jobs
from mfsample.planning.runner import JOB

if __name__ == "__main__":
  jobs.main(JOB)
