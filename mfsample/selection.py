"""The next view and the next light: select among candidates, or ascend U from a start.

For a stochastic field and M samples z (`mfsample.samplers.sample_z`):

* `next_views(model, candidates, z, k)`: the k candidate cameras of highest U (Eq. 10), the
  paper's Ours (Sel.); `optimize_view(model, camera, z)`: Adam on -U from a start pose along
  its orbit about a target, the paper's Ours (Opt.) (Sec. 4.4).
* `next_lights(model, cameras, z, lights, k)`: the k candidate SH lights of highest
  U(xi) = xi^T Q xi over `cameras` (a relightable field, `mfsample.lighting`);
  `optimize_light(model, cameras, z, light)`: projected Adam on U(xi) over the sphere of
  lights of the start's norm (Sec. 5.2).

Each grows its render budget on the host where a render overflows (never a truncated image)
and runs its renders jitted: call them eagerly, from any program, and compare what they
return. Lights are compared at one norm: U(c xi) = c^2 U(xi).
"""

import jax
import numpy as np

from mfsample import arg_checks
from mfsample.camera import Camera
from mfsample.lighting import lights as lights_lib
from mfsample.lighting import optimize as light_optimize
from mfsample.lighting import uncertainty as light_u
from mfsample.model import Model
from mfsample.planning import optimize as view_optimize
from mfsample.renderer.settings import RenderSettings
from mfsample.view_uncertainty import score_cameras


def top_k(values, k):
  """Indices of the k largest `values` [B], largest first (ties: the lower index first); all
  B of them when k > B.

  Raises:
    ValueError: k is not an integer >= 0, `values` is not one axis of real numbers, or a
      value is NaN (an unknown score, e.g. U of an invalid camera, cannot be ranked).
  """
  k = arg_checks.check_int("k", k, minimum=0)
  arg_checks.check_real_dtype("values", values)
  values = np.asarray(values, np.float64)
  if values.ndim != 1:
    raise ValueError(f"values must have shape [B], got {list(values.shape)}")
  nan = np.flatnonzero(np.isnan(values))
  if nan.size:
    raise ValueError(f"values[{int(nan[0])}] is NaN ({nan.size} of {values.size}): a score "
                     "that is not a number cannot be ranked")
  order = np.lexsort((np.arange(len(values)), -values))
  return order[:min(k, len(values))]


def next_views(model: Model, candidates: Camera, z: jax.Array, k: int, *,
               settings: RenderSettings = RenderSettings(),
               background: jax.Array | None = None, chunk_size: int = 1,
               max_budget: int = 1 << 24) -> tuple[np.ndarray, np.ndarray]:
  """The `k` candidate views of highest U (Eq. 10): the next views to capture.

  Args:
    model: a stochastic `mfsample.Model`.
    candidates: `Camera` batched over [C] (e.g. `mfsample.sphere_cameras`).
    z: `[M, *z_shape]` samples of U (`mfsample.sample_z`; M >= 2).
    k: how many to return (all C when k > C).
    settings: starting `RenderSettings` (the budget grows where a render overflows).
    background: [3] colour behind the Gaussians (default black).
    chunk_size: candidates rendered together (vmapped).
    max_budget: refuse to grow the budget beyond this (`BudgetExceededError`).

  Returns:
    (indices [min(k, C)] int numpy, highest U first (ties: the lower index); scores [C] U
    of every candidate, numpy).
  """
  k = arg_checks.check_int("k", k, minimum=1)
  scores, _ = score_cameras(model, candidates, z, settings=settings, background=background,
                            chunk_size=chunk_size, max_budget=max_budget)
  values = np.asarray(scores.values)
  return top_k(values, k), values


def optimize_view(model: Model, camera: Camera, z: jax.Array, *, steps: int = 400,
                  learning_rate: float = 5e-4, target: tuple = (0.0, 0.0, 0.0),
                  z_drop_step: int | None = None, z_drop_scale: float = 0.1,
                  v_range: tuple = (0.01, 0.99), settings: RenderSettings = RenderSettings(),
                  background: jax.Array | None = None, max_budget: int = 1 << 24) -> Camera:
  """Gradient ascent of U from `camera` (the paper's view optimisation, Sec. 4.4).

  The camera moves on the sphere about `target` through its start, always looking at
  `target` with +z up (the spherical parameterisation of the authors' code: (u, v) =
  (azimuth / 2 pi, polar / pi), v kept in `v_range`); Adam on -U for `steps` steps, with z
  scaled by `z_drop_scale` from `z_drop_step` on (the authors: 400 steps, lr 5e-4, z x 0.1
  from step 200), so the second half follows a smoother, more local variance.

  Args:
    model: a stochastic `mfsample.Model`.
    camera: the start, an unbatched `Camera` (its intrinsics and size are kept).
    z: `[M, *z_shape]` samples (`mfsample.sample_z`; the paper: M = 2).
    steps: Adam steps (>= 1).
    learning_rate: Adam's rate on (u, v) (>= 0).
    target: [3] the point the camera orbits and looks at (the scene's centre).
    z_drop_step: from this step on z is scaled (default: steps // 2).
    z_drop_scale: the scale (in [0, 1]).
    v_range: (v_min, v_max) of the polar coordinate v = polar / pi.
    settings: starting `RenderSettings` (grown on overflow).
    background: [3] colour behind the Gaussians (default black).
    max_budget: refuse to grow the budget beyond this.

  Returns:
    the final `Camera` (unbatched, the start's intrinsics).
  """
  steps = arg_checks.check_int("steps", steps, minimum=1)
  opt = view_optimize.OptimizeSettings(
      steps=steps, lr=arg_checks.check_float("learning_rate", learning_rate, minimum=0.0),
      z_drop_step=steps // 2 if z_drop_step is None else z_drop_step,
      z_drop_scale=z_drop_scale)
  result = view_optimize.optimize_orbit(model, camera, z, target=target, v_range=v_range,
                                        opt=opt, settings=settings, background=background,
                                        max_budget=max_budget)
  return result.camera


def next_lights(model: Model, cameras: Camera, z: jax.Array, lights: np.ndarray, k: int, *,
                settings: RenderSettings = RenderSettings(),
                max_budget: int = 1 << 24) -> tuple[np.ndarray, np.ndarray]:
  """The `k` candidate lights of highest U(xi) over `cameras`: the next lights to capture.

  U(xi) = xi^T Q xi exactly (`mfsample.lighting.uncertainty`): Q is rendered once (one render
  per sample and camera), every candidate is then scored without rendering. Give the
  candidates one norm (U(c xi) = c^2 U(xi): a brighter light is not a more informative one).

  Args:
    model: a stochastic relightable `Model` (`mfsample.lighting.init_relightable`).
    cameras: `Camera` [B] where the next captures will be taken (U summed over them).
    z: `[M, *z_shape]` samples (`mfsample.sample_z`).
    lights: [L, n] candidate SH lights (`mfsample.lighting.uniform_light`, ...).
    k: how many to return.
    settings: starting `RenderSettings`.
    max_budget: refuse to grow the budget beyond this.

  Returns:
    (indices [min(k, L)] int numpy, highest U first; scores [L] U(xi) of every candidate).
  """
  k = arg_checks.check_int("k", k, minimum=1)
  _, n = light_u._check_model(model)
  lights = lights_lib.check_lights(lights, n)
  gram, _ = light_u.light_gram(model, cameras, z, settings=settings, max_budget=max_budget)
  scores = np.asarray(light_u.quadratic_u(np.asarray(gram.q, np.float64), lights))
  return top_k(scores, k), scores


def optimize_light(model: Model, cameras: Camera, z: jax.Array, light: np.ndarray, *,
                   steps: int = 100, learning_rate: float = 0.05,
                   final_learning_rate: float = 0.005,
                   settings: RenderSettings = RenderSettings(),
                   max_budget: int = 1 << 24) -> np.ndarray:
  """Gradient ascent of U(xi) over `cameras` from `light`, on the sphere of its norm.

  Projected Adam through the renderer (the paper's light optimiser; its numbers are ours,
  `mfsample.lighting.optimize`): the gradient's radial part is removed and every step is
  projected back onto `|xi| = |light|`; the rate decays along a cosine from `learning_rate` to
  `final_learning_rate`.

  Args:
    model: a stochastic relightable `Model`.
    cameras: `Camera` [B] over which U is summed.
    z: `[M, *z_shape]` samples.
    light: [n] the start (non-zero).
    steps: Adam steps.
    learning_rate, final_learning_rate: the cosine schedule's ends.
    settings: starting `RenderSettings`.
    max_budget: refuse to grow the budget beyond this.

  Returns:
    [n] float64 numpy, the final light (`|result| = |light|`).
  """
  _, n = light_u._check_model(model)
  light = lights_lib.check_light(light, n, "light")
  norm = float(np.linalg.norm(light))
  if not norm > 0:
    raise ValueError("light must not be zero (its norm is the sphere the ascent stays on)")
  opt = light_optimize.AscentSettings(steps=steps, lr=learning_rate,
                                      final_lr=final_learning_rate, norm=norm)
  return light_optimize.ascend(model, cameras, z, light, opt=opt, settings=settings,
                               max_budget=max_budget).light
