"""Active camera planning (paper Sec. 4.4, 5.1): strategies, view optimisation, the protocol.

* `poses`: the spherical parameterisation (u, v) and free 6-DoF poses (se(3) exponential).
* `optimize`: Adam on -U w.r.t. the camera (the authors' recipe, every number a setting).
* `strategies`: random, farthest point, ActiveNeRF-style variance, FisherRF, ACP and the
  three variants of ours, behind one interface.
* `runner`: the protocol as pure steps and a thin, resumable loop (`run_camera_planning`).
* `workdirs`: what a planning workdir holds and when a later call may add runs to it
  (`restore_runs` seeds a workdir with a results directory's finished runs).
* `tables`: Table 1, the paired differences and the other tables, from run records.
* `by_seeds`: those tables over a range of a run's seeds (or of its final models).
"""

from mfsample.planning.optimize import (
                                        OptimizeResult,
                                        OptimizeSettings,
                                        optimize_se3,
                                        optimize_spherical,
)
from mfsample.planning.poses import (
                                        SphereSpec,
                                        camera_to_uv,
                                        perturb_camera,
                                        project_uv,
                                        se3_exp,
                                        spherical_camera,
)
from mfsample.planning.runner import run_camera_planning
from mfsample.planning.strategies import NAMES, Choice, Inputs, Strategy, make_strategy
from mfsample.planning.workdirs import restore_runs

__all__ = [
    "NAMES", "Choice", "Inputs", "OptimizeResult", "OptimizeSettings", "SphereSpec",
    "Strategy", "camera_to_uv", "make_strategy", "optimize_se3", "optimize_spherical",
    "perturb_camera", "project_uv", "restore_runs", "run_camera_planning", "se3_exp",
    "spherical_camera",
]
