"""Relightable stochastic field and active illumination planning (paper Sec. 5.2).

* `field`: per-Gaussian transfer matrices T (m outgoing x n light SH coefficients x 3) in
  place of SH colour; radiance linear in the light; `init_relightable`, `render_relit`.
* `lights`: SH lights, the uniform light and the common norm, held-out test lights.
* `captures`: the oracle's basis images per camera, and captures under any light.
* `training`: `fit_relightable`, the colour field's step and loop on (view, light) captures.
* `uncertainty`: U(xi) over cameras (differentiable) and its quadratic form Q.
* `optimize`: projected Adam on U over the sphere of lights.
* `strategies`: random, Sobol, orthogonal random, Ours, Ours (exact), behind one interface.

The protocol (a job: it reads its `ml_collections` config) is `protocol`
(`run_light_planning(config, workdir)`), with `config`, `evaluate`, `tables`, `figures`.
"""

from mfsample.lighting.captures import LightData, capture
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
from mfsample.lighting.strategies import (
                                     NAMES,
                                     LightChoice,
                                     LightInputs,
                                     LightStrategy,
                                     make_light_strategy,
)
from mfsample.lighting.training import fit_relightable
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
    "canonical_sign", "capture", "check_light", "coefficient_counts", "fit_relightable",
    "held_out_lights", "init_relightable", "light_gram", "light_pixel_map", "light_uncertainty",
    "light_uncertainty_fitted", "make_light_strategy", "on_sphere",
    "quadratic_u", "radiance", "relit_gaussians", "render_basis", "render_relit",
    "top_eigen", "uniform_light",
]
