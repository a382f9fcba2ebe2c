"""Active camera planning (paper Sec. 4.4, 5.1): view optimisation, strategies, the protocol.

The library's pieces:

* `poses`: the spherical parameterisation (u, v) and free 6-DoF poses (se(3) exponential).
* `optimize`: Adam on -U w.r.t. the camera (the authors' recipe, every number a setting).
* `strategies`: random, farthest point, ActiveNeRF-style variance, FisherRF, ACP and the
  variants of ours, behind one interface, with their typed settings.
* `u_error`: how well U ranks candidates by the model's error there.

The protocol (the main job) reads its `ml_collections` config: `config` (its defaults and
validator), `runner` (`run_camera_planning(config, workdir)`), `pool`, `training`,
`tables`, `figures`, `rounds`.
"""

from mfsample.planning.optimize import (
    OptimizeResult,
    OptimizeSettings,
    optimize_orbit,
    optimize_se3,
    optimize_spherical,
)
from mfsample.planning.poses import (
    SphereSpec,
    camera_to_uv,
    orbit_camera,
    perturb_camera,
    project_uv,
    se3_exp,
    spherical_camera,
)
from mfsample.planning.strategies import (
    NAMES,
    Choice,
    Inputs,
    Strategy,
    StrategySettings,
    make_strategy,
)

__all__ = [
    "NAMES", "Choice", "Inputs", "OptimizeResult", "OptimizeSettings", "SphereSpec",
    "Strategy", "StrategySettings", "camera_to_uv", "make_strategy", "optimize_orbit",
    "optimize_se3", "optimize_spherical", "orbit_camera", "perturb_camera", "project_uv",
    "se3_exp", "spherical_camera",
]
