"""The capture planner in the browser: a job's workdir shown with viser (docs/viewer.md).

  python experiments/viewer.py --workdir=workdirs/camera_planning
  python experiments/viewer.py --workdir=workdirs/camera_planning --screenshot=page.png

Opens the workdir of the your-data job (experiments/next_views.py), camera planning or light
planning, finished or running, and prints the address to open. Binds to this machine only
(127.0.0.1) unless --host says otherwise; a running job's new steps appear as it writes them.
The same command installed: `mfsample viewer` (`mfsample.viewer.command`).
"""

from mfsample.viewer.command import main

if __name__ == "__main__":
  main()
