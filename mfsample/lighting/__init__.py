"""Relightable stochastic field and active illumination planning (paper Sec. 5.2).

* `field`: per-Gaussian transfer matrices T (m outgoing x n light SH coefficients x 3) in
  place of SH colour; radiance linear in the light; `init_relightable`, `render_relit`.
* `lights`: SH lights, the uniform light and the common norm, held-out test lights.
* `captures`: the oracle's basis images per camera, and captures under any light.
* `training`: the jitted step on (view, light) captures and its thin loop.
* `uncertainty`: U(xi) over cameras (differentiable) and its quadratic form Q.
* `optimize`: projected Adam on U over the sphere of lights.
* `strategies`: random, Sobol, orthogonal random, Ours, Ours (exact), behind one interface.
* `protocol`: the protocol's pure steps and the resumable loop `run_light_planning`.
* `evaluate`, `tables`, `figures`: relit test views, the table and the figures of a run.
* `config`: the protocol's config and its defaults (`default_config`).
"""

from mfsample.lighting.captures import LightData, capture, make_light_data
from mfsample.lighting.config import default_config
from mfsample.lighting.field import (
                                     coefficient_counts,
                                     init_relightable,
                                     radiance,
                                     relit_gaussians,
                                     render_basis,
                                     render_relit,
)
from mfsample.lighting.lights import (
                                      UNIFORM_NORM,
                                      canonical_sign,
                                      check_light,
                                      held_out_lights,
                                      on_sphere,
                                      uniform_light,
)
from mfsample.lighting.optimize import AscentResult, AscentSettings, ascend
from mfsample.lighting.protocol import run_light_planning
from mfsample.lighting.strategies import (
                                          NAMES,
                                          LightChoice,
                                          LightInputs,
                                          LightStrategy,
                                          make_light_strategy,
)
from mfsample.lighting.uncertainty import (
                                           LightGram,
                                           LightUncertainty,
                                           light_gram,
                                           light_pixel_map,
                                           light_uncertainty,
                                           light_uncertainty_fitted,
                                           quadratic_u,
                                           top_eigen,
)

__all__ = [
    "NAMES", "UNIFORM_NORM", "AscentResult", "AscentSettings", "LightChoice", "LightData",
    "LightGram", "LightInputs", "LightStrategy", "LightUncertainty", "ascend",
    "canonical_sign", "capture", "check_light", "coefficient_counts", "default_config",
    "held_out_lights", "init_relightable", "light_gram", "light_pixel_map", "light_uncertainty",
    "light_uncertainty_fitted", "make_light_data", "make_light_strategy", "on_sphere",
    "quadratic_u", "radiance", "relit_gaussians", "render_basis", "render_relit",
    "run_light_planning", "top_eigen", "uniform_light",
]
