"""Active illumination planning: every light strategy, one training run each, figures.

  python experiments/light_planning.py --config=configs/light_planning.py \
      --workdir=workdirs/light_planning

Writes results.json, table.md, metrics.png, relit.png and u_sphere.png to the workdir.
Running again on the same workdir resumes: finished strategies are loaded, an interrupted
one restarts at its last finished light.
"""

from mfsample import jobs
from mfsample.lighting.protocol import JOB

if __name__ == "__main__":
  jobs.main(JOB)
