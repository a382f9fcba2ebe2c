"""Next-light strategies behind one interface: (model, cameras, lights used) -> the next light.

`STRATEGIES` is the registry: every strategy's name, label, function and random stream.

Every strategy returns a light of the same norm, |xi| = `LightInputs.norm` (by default the
uniform light's, sqrt(4 pi)), because U(c xi) = c^2 U(xi): lights of different norms cannot
be ranked by U, and a brighter light is not a more informative one for a linear model. A
light and its negative have the same U and teach the same thing; each strategy returns the
one with a positive DC coefficient (`lights.canonical_sign`).

| name       | label               | the next light                                           |
| ---------- | ------------------- | -------------------------------------------------------- |
| random     | Random              | uniform on the sphere                                    |
| sobol      | Sobol               | the next point of a scrambled Sobol sequence in [0, 1]^n,|
|            |                     | mapped to the sphere (inverse normal CDF, normalised)    |
| orthogonal | Orthogonal random   | uniform on the sphere of the complement of the lights    |
|            |                     | used: new but not uncertainty-guided (a control)         |
| ours       | Ours                | the one-hot light of highest U, then projected Adam on   |
|            |                     | U(xi) through the renderer (the paper's method)          |
| ours_exact | Ours (exact)        | the top eigenvector of Q (U(xi) = xi^T Q xi): the maximum|
|            |                     | of U on the sphere, which no paper reports; it checks    |
|            |                     | the ascent                                               |

U(xi) of a one-hot light is norm^2 Q_jj exactly, so Ours reads the best one-hot off Q's
diagonal (one render per sample and camera for all n one-hots; the same numbers as
rendering each).
"""

from collections.abc import Callable
from typing import NamedTuple

import jax
import numpy as np

from mfsample import streams
from mfsample.lighting import lights as lights_lib
from mfsample.lighting import optimize as opt_lib
from mfsample.lighting import uncertainty as lu
from mfsample.renderer.settings import RenderSettings


class LightRenders(NamedTuple):
  """The render settings that sufficed before for U over the cameras and for the ascent's
  renders (None: not known yet)."""

  u: RenderSettings | None = None
  ascent: RenderSettings | None = None


class LightInputs(NamedTuple):
  """What a strategy sees when it chooses light number `index` (0-based; 0 is the uniform
  light, which no strategy chooses).

  Attributes:
    model: the relightable model trained on the lights used so far.
    cameras: `Camera` [B] over which U is summed.
    z: `[M, *z_shape]` samples of U.
    q: [n, n] Q of U(xi) = xi^T Q xi for this model, cameras and z.
    used: [index, n] the lights used so far.
    index: the number of lights used so far.
    norm: the common norm of the lights.
    ascent: `optimize.AscentSettings` (Ours).
    renders: `LightRenders` that sufficed before.
    sobol_seed: scrambling seed of the Sobol strategy.
  """

  model: object
  cameras: object
  z: object
  q: np.ndarray
  used: np.ndarray
  index: int
  norm: float
  ascent: opt_lib.AscentSettings
  renders: LightRenders = LightRenders()
  sobol_seed: int = 1


class LightChoice(NamedTuple):
  """A strategy's answer.

  Attributes:
    light: [n] float64, `|light| = norm`, positive DC coefficient.
    info: json-able extras.
    renders: the inputs' `LightRenders`, with those the strategy grew.
  """

  light: np.ndarray
  info: dict
  renders: LightRenders


class LightStrategy(NamedTuple):
  """A next-light strategy (see the module docstring)."""

  name: str
  select: Callable[[LightInputs, jax.Array], LightChoice]

  @property
  def label(self):
    return STRATEGIES[self.name].label if self.name in STRATEGIES else self.name


def _rng(key):
  return np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel().tolist())


def _finish(xi, inputs, info=None):
  light = lights_lib.canonical_sign(lights_lib.on_sphere(xi, inputs.norm))
  return LightChoice(light, dict(info or {}), inputs.renders)


def random_light(inputs: LightInputs, key) -> LightChoice:
  """Uniform on the sphere: a standard normal vector, normalised."""
  return _finish(_rng(key).normal(size=inputs.q.shape[0]), inputs)


def sobol_light(inputs: LightInputs, key) -> LightChoice:
  """Point `index - 1` of a scrambled Sobol sequence in [0, 1]^n (seed `sobol_seed`), mapped
  to the sphere through the inverse normal CDF (uniform directions for uniform points)."""
  del key
  from scipy.special import ndtri
  from scipy.stats import qmc

  n = inputs.q.shape[0]
  engine = qmc.Sobol(d=n, scramble=True, seed=int(inputs.sobol_seed))
  if inputs.index > 1:
    engine.fast_forward(inputs.index - 1)
  point = np.clip(engine.random(1)[0], 1e-9, 1.0 - 1e-9)
  return _finish(ndtri(point), inputs, {"sobol_index": inputs.index - 1})


def orthogonal_light(inputs: LightInputs, key) -> LightChoice:
  """Uniform on the unit sphere of the orthogonal complement of the lights used."""
  n = inputs.q.shape[0]
  used = np.asarray(inputs.used, np.float64).reshape(-1, n)
  _, s, vt = np.linalg.svd(used, full_matrices=True)
  rank = int(np.sum(s > 1e-9 * max(float(s.max(initial=0.0)), 1e-300)))
  if rank >= n:
    raise ValueError(f"the orthogonal strategy has no new direction left: the {len(used)} "
                     f"lights used span all {n} coefficients")
  complement = vt[rank:]  # [n - rank, n] orthonormal rows
  return _finish(complement.T @ _rng(key).normal(size=n - rank), inputs)


def best_one_hot(q, norm):
  """(index j, U) of the one-hot light norm e_j of highest U = norm^2 Q_jj."""
  diag = np.diag(np.asarray(q, np.float64))
  j = int(np.argmax(diag))
  return j, float(norm ** 2 * diag[j])


def ours_light(inputs: LightInputs, key) -> LightChoice:
  """The best one-hot light, then projected Adam on U(xi) (`optimize.ascend`)."""
  del key
  n = inputs.q.shape[0]
  j, u_one_hot = best_one_hot(inputs.q, inputs.norm)
  start = np.zeros(n)
  start[j] = inputs.norm
  result = opt_lib.ascend(inputs.model, inputs.cameras, inputs.z, start, opt=inputs.ascent,
                          settings=inputs.renders.ascent or inputs.renders.u)
  info = {"one_hot": j, "u_one_hot": u_one_hot, "u_start": float(result.values[0]),
          "u_end": result.value, "values": result.values.tolist()}
  return _finish(result.light,
                 inputs._replace(renders=inputs.renders._replace(ascent=result.settings)), info)


def ours_exact_light(inputs: LightInputs, key) -> LightChoice:
  """The top eigenvector of Q at the common norm."""
  del key
  value, vector = lu.top_eigen(inputs.q)
  return _finish(vector, inputs, {"top_eigenvalue": value})


class LightStrategySpec(NamedTuple):
  """A registered light strategy: its label, its function and its random stream
  (`mfsample.streams`: fixed with the strategy, not its place in the registry)."""

  label: str
  select: Callable[[LightInputs, jax.Array], LightChoice]
  stream: int


STRATEGIES = {
    "random": LightStrategySpec("Random", random_light, 0),
    "sobol": LightStrategySpec("Sobol", sobol_light, 1),
    "orthogonal": LightStrategySpec("Orthogonal random", orthogonal_light, 2),
    "ours": LightStrategySpec("Ours", ours_light, 3),
    "ours_exact": LightStrategySpec("Ours (exact)", ours_exact_light, 4),
}
streams.check_streams(STRATEGIES, "light strategies")
NAMES = tuple(STRATEGIES)


def make_light_strategy(name) -> LightStrategy:
  """The strategy `name` (one of `NAMES`)."""
  if name not in STRATEGIES:
    raise ValueError(f"unknown light strategy {name!r}; known: {', '.join(NAMES)}")
  return LightStrategy(name, STRATEGIES[name].select)


def strategy_key(seed, name, index):
  """The PRNG key of strategy `name` choosing light number `index` for `seed`."""
  return streams.stream_key(seed, STRATEGIES[name].stream, index)
