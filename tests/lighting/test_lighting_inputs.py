"""Hostile inputs to mfsample.lighting: relightable models, lights, Q.

For each entry point, a table of bad inputs and what they give: each row is a bad input and
its expected outcome, a clear error whose message names the field or the file, or a defined
behaviour (docs/reliability.md lists the same tables).
"""

import jax
import numpy as np
import pytest
from hostile_testlib import NAN, POINTS, RELIGHTABLE, SMALL, _cams, _relightable

from mfsample.lighting import captures, lights
from mfsample.lighting import field as light_field
from mfsample.lighting import optimize as light_optimize
from mfsample.lighting import uncertainty as lu
from mfsample.lighting.field import init_relightable

# ====================================================================== init_relightable


@pytest.mark.parametrize("changes, message", [
    ({"points": np.where(np.arange(5)[:, None] == 2, NAN, POINTS)}, r"points\[2\] is not finite"),
    ({"init_opacity": 1.0}, r"init_opacity must be a finite number in \(0.0, 1.0\), got 1.0"),
    ({"capacity": 3}, "capacity 3 < number of points 5"),
    ({"init_scales": {"transfer_dc": NAN}}, r"init_scales\['transfer_dc'\] must be a finite"),
    ({"key": 7}, "key must be one JAX PRNG key"),
    ({"light_coeffs": 5}, r"light_coeffs \(n\) must be one of \(1, 4, 9, 16\)"),
])
def test_init_relightable_table(changes, message):
  kwargs = {"key": jax.random.PRNGKey(0), "points": POINTS, "spec": RELIGHTABLE, "out_coeffs": 1,
            "light_coeffs": 4, "init_scales": {"transfer_dc": 0.1}, **changes}
  with pytest.raises(ValueError, match=message):
    init_relightable(**kwargs)


# ====================================================================== lights, Q


@pytest.mark.parametrize("call, message", [
    (lambda: lights.on_sphere(np.array([NAN, 1.0, 0.0, 0.0])), r"xi\[0\] is not finite"),
    (lambda: lights.on_sphere(np.zeros(4)), "a zero light has no direction"),
    (lambda: lights.on_sphere(np.ones(4), norm=0.0), "norm must be a finite number > 0.0"),
    (lambda: lights.uniform_light(5), "an SH light has 1, 4, 9 or 16 coefficients, got 5"),
    (lambda: lights.held_out_lights(4, num_environments=1, num_random=-1, seed=0),
     "num_random must be an integer >= 0, got -1"),
    (lambda: lights.held_out_lights(4, num_environments=0, num_random=0, seed=0),
     "num_environments \\+ num_random >= 1"),
    (lambda: lights.held_out_lights(4, num_environments=1, num_random=1, seed=0, power=0.0),
     "power must be a finite number > 0.0"),
    (lambda: lights.held_out_lights(4, num_environments=1, num_random=1, seed=-2),
     "seed must be an integer in"),
    (lambda: lu.top_eigen(np.full((4, 4), NAN)), r"q\[0, 0\] is not finite"),
    (lambda: lu.top_eigen(np.ones((4, 3))), r"q must be a square \[n, n\] matrix, got shape "
                                            r"\[4, 3\]"),
    (lambda: lu.top_eigen(np.triu(np.ones((4, 4)))), r"q must be symmetric .*max \|Q - Q\^T\| = 1"),
    (lambda: lu.quadratic_u(np.eye(4), np.ones((2, 3))), r"lights must have shape \[\.\.\., 4\]"),
    (lambda: lu.quadratic_u(np.eye(4)[:3], np.ones(4)), "q must be a square"),
    (lambda: captures.capture(np.zeros((2, 4, 8, 8)), np.ones(4)),
     r"basis must have shape \[V, n, H, W, 3\]"),
    (lambda: light_optimize.AscentSettings(steps=2.5), "AscentSettings.steps must be an integer"),
    (lambda: light_optimize.AscentSettings(norm=NAN), "AscentSettings.norm must be a finite"),
    (lambda: light_field.radiance(_relightable().params.mean, np.ones(3), np.zeros((5, 3))),
     r"xi must be one SH light of 4 coefficients \(shape \[4\]\), got shape \[3\]"),
    (lambda: lu.light_uncertainty(_relightable(), _cams()[0], np.zeros((2, 2), np.float32),
                                  np.ones(4), settings=SMALL),
     r"cameras must be a Camera batched over one axis \[B\], got batch shape \(\)"),
])
def test_light_argument_table(call, message):
  with pytest.raises(ValueError, match=message):
    call()
