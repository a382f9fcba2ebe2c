"""Active camera planning (paper Sec. 4.4, 5.1): strategies, view optimisation, the protocol.

* `poses`: the spherical parameterisation (u, v) and free 6-DoF poses (se(3) exponential).
* `optimize`: Adam on -U w.r.t. the camera (the authors' recipe, every number a setting).
* `strategies`: random, farthest point, ActiveNeRF-style variance, FisherRF, ACP and the
  three variants of ours, behind one interface.
* `runner`: the protocol as pure steps and a thin, resumable loop (`run_camera_planning`).
* `tables`: Table 1, the paired differences and the other tables, from run records.
* `config`: the protocol's config and its defaults (`default_config`).
"""

from mfsample.planning.config import default_config
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

__all__ = [
    "NAMES", "Choice", "Inputs", "OptimizeResult", "OptimizeSettings", "SphereSpec",
    "Strategy", "camera_to_uv", "default_config", "make_strategy", "optimize_se3",
    "optimize_spherical", "perturb_camera", "project_uv", "run_camera_planning", "se3_exp",
    "spherical_camera",
]
