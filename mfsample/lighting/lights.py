"""SH lights: the uniform light and the common norm, validation, environments projected to SH.

A light xi in R^n is the white distant environment L(w) = sum_b xi_b Y_b(w), with w a unit
world direction towards the sky and Y the renderer's real SH basis (`mfsample.renderer.sh`),
the convention of the capture oracle (`mfsample.scenes.capture_sh_basis`). The basis is
orthonormal, so |xi|^2 = integral over the sphere of L(w)^2.

The uniform light L = 1 is xi = sqrt(4 pi) e_0 (Y_0 = 1 / sqrt(4 pi)); under it a diffuse
surface of albedo rho shows radiance rho (unoccluded). Its norm sqrt(4 pi) (`UNIFORM_NORM`)
is the norm at which every light strategy's lights are compared: U(c xi) = c^2 U(xi), so
only lights of one norm can be ranked by U.

Lights may be signed (L < 0 in some directions): for the linear oracle a signed light is
exact (the image of its positive part minus that of its negative part), and in a lab it costs
two captures. The held-out test lights (`held_out_lights`) are all non-negative.
"""

import math

import numpy as np

from mfsample import arg_checks
from mfsample.renderer import sh as sh_lib

UNIFORM_NORM = math.sqrt(4.0 * math.pi)  # |xi| of the uniform light L = 1.


def uniform_light(n):
  """[n] the uniform light L = 1 (only the DC coefficient, sqrt(4 pi))."""
  degree_of(n)
  xi = np.zeros(n)
  xi[0] = UNIFORM_NORM
  return xi


def check_light(xi, n, name="xi"):
  """`xi` as a float64 [n] numpy array; ValueError naming `name` unless it is one finite
  light of n coefficients."""
  arr = np.asarray(xi)
  if arr.ndim != 1 or arr.shape[0] != n:
    raise ValueError(f"{name} must be one SH light of {n} coefficients (shape [{n}]), got "
                     f"shape {list(arr.shape)}")
  if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
    raise ValueError(f"{name} must hold real numbers, got dtype {arr.dtype}")
  arr = arr.astype(np.float64)
  bad = np.flatnonzero(~np.isfinite(arr))
  if bad.size:
    raise ValueError(f"{name} has non-finite coefficients at {bad.tolist()}: {arr[bad].tolist()}")
  return arr


def check_lights(lights, n, name="lights"):
  """`lights` as a float64 [B, n] numpy array (each checked as by `check_light`)."""
  arr = np.asarray(lights)
  if arr.ndim != 2 or arr.shape[1] != n:
    raise ValueError(f"{name} must be a batch of SH lights of {n} coefficients (shape "
                     f"[B, {n}]), got shape {list(arr.shape)}")
  return np.stack([check_light(x, n, f"{name}[{i}]") for i, x in enumerate(arr)]) \
      if len(arr) else arr.astype(np.float64)


def on_sphere(xi, norm=UNIFORM_NORM):
  """xi scaled to `|xi| = norm` (ValueError for a zero light, which has no direction)."""
  arg_checks.check_real_dtype("xi", xi)
  xi = np.asarray(xi, np.float64)
  arg_checks.check_finite("xi", xi)
  arg_checks.check_float("norm", norm, above=0.0)
  length = float(np.linalg.norm(xi))
  if not length > 0.0:
    raise ValueError("a zero light has no direction to scale to the common norm")
  return xi * (norm / length)


def canonical_sign(xi):
  """xi or -xi, whichever has a positive DC coefficient (else its first non-zero one).

  A light and its negative have the same U and teach a linear model the same thing (the
  loss is symmetric under negating both image and prediction); the strategies return the
  brighter of the two.
  """
  xi = np.asarray(xi, np.float64)
  nonzero = np.flatnonzero(np.abs(xi) > 0)
  return -xi if nonzero.size and xi[nonzero[0]] < 0 else xi


def degree_of(n):
  """SH degree l of n = (l + 1)^2 coefficients."""
  if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
    raise ValueError(f"an SH light has 1, 4, 9 or 16 coefficients, got {n!r}")
  degree = math.isqrt(int(n)) - 1
  if (degree + 1) ** 2 != n or not 0 <= degree <= 3:
    raise ValueError(f"an SH light has 1, 4, 9 or 16 coefficients, got {n}")
  return degree


# ------------------------------------------------------------------------- the sphere


def direction_grid(height=64, width=128):
  """Unit world directions at the centres of a latitude-longitude grid, and solid angles.

  Row i has polar angle theta = pi (i + 1/2) / height from +z (the sky), column j azimuth
  phi = 2 pi (j + 1/2) / width from +x towards +y.

  Returns:
    (dirs [h, w, 3], weights [h, w] solid angle of each cell, summing to 4 pi).
  """
  theta = np.pi * (np.arange(height) + 0.5) / height
  phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
  theta, phi = np.meshgrid(theta, phi, indexing="ij")
  dirs = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)],
                  axis=-1)
  weights = np.sin(theta) * (np.pi / height) * (2.0 * np.pi / width)
  return dirs, weights * (4.0 * np.pi / weights.sum())


def basis_values(dirs, n):
  """[..., n] Y_b(dirs) (float64 numpy)."""
  return np.asarray(sh_lib.sh_basis(np.asarray(dirs, np.float32), degree_of(n)), np.float64)


def environment(xi, dirs):
  """[...] radiance L(dirs) = sum_b xi_b Y_b(dirs) of the light xi."""
  xi = np.asarray(xi, np.float64)
  return basis_values(dirs, xi.shape[-1]) @ xi


def project(values, dirs, weights, n):
  """[n] SH coefficients of the environment sampled as `values` at `dirs` (quadrature with
  the solid angles `weights`): xi_b = integral of L Y_b."""
  y = basis_values(dirs, n).reshape(-1, n)
  return (np.asarray(values, np.float64).ravel() * np.ravel(weights)) @ y


def point_light(direction, n, norm=UNIFORM_NORM):
  """[n] the SH projection of a light from one direction (xi_b = Y_b(direction)), at `norm`."""
  return on_sphere(basis_values(np.asarray(direction, np.float64), n), norm)


# ------------------------------------------------------------------------- test lights


def _random_direction(rng):
  v = rng.normal(size=3)
  return v / np.linalg.norm(v)


def environment_light(rng, n, dirs, weights, sharpness=(2.0, 8.0), max_lobes=2):
  """A smooth non-negative environment (ambient plus 1..max_lobes von Mises-Fisher lobes
  exp(kappa (w . mu - 1)) of random directions, sharpness kappa and weights) projected to SH.

  Truncation to n coefficients rings slightly negative near sharp lobes; the DC coefficient
  is then raised until the SH light is non-negative on the grid `dirs`.
  """
  values = np.full(dirs.shape[:-1], rng.uniform(0.0, 0.1))
  for _ in range(int(rng.integers(1, max_lobes + 1))):
    kappa = rng.uniform(*sharpness)
    values = values + rng.uniform(0.5, 1.0) * np.exp(kappa * (dirs @ _random_direction(rng)
                                                              - 1.0))
  xi = project(values, dirs, weights, n)
  lowest = float(np.min(environment(xi, dirs)))
  if lowest < 0.0:
    xi[0] -= lowest * UNIFORM_NORM  # a constant c is c sqrt(4 pi) in xi_0
  return xi


def random_nonnegative_light(rng, n, dirs, fraction=(0.5, 1.0)):
  """The uniform light plus a random direction in the other coefficients, scaled to a random
  `fraction` of the largest amount that keeps the light non-negative on the grid `dirs`."""
  xi = uniform_light(n)
  if n == 1:
    return xi
  rest = np.zeros(n)
  rest[1:] = rng.normal(size=n - 1)
  dip = float(np.max(-environment(rest, dirs)))  # > 0: a zero-mean function dips below 0
  xi += rng.uniform(*fraction) * rest / dip  # the uniform light's radiance is 1
  return xi


def held_out_lights(n, *, num_environments, num_random, seed, power=1.0, sharpness=(2.0, 8.0),
                grid=(64, 128)):
  """Held-out test lights: smooth environments and random SH lights, all non-negative.

  Every light is scaled to the mean radiance `power` (its DC coefficient power sqrt(4 pi)):
  the total power of `power` times the uniform light.

  Returns:
    (lights [K, n], kinds: K strings "environment" or "random"), K = num_environments +
    num_random >= 1.
  """
  degree_of(n)
  counts = [arg_checks.check_int(name, value, minimum=0) for name, value in
            (("num_environments", num_environments), ("num_random", num_random))]
  if sum(counts) < 1:
    raise ValueError("held_out_lights needs num_environments + num_random >= 1, got 0")
  arg_checks.check_seed("seed", seed)
  arg_checks.check_float("power", power, above=0.0)
  if len(sharpness) != 2:
    raise ValueError(f"sharpness must be (low, high), got {sharpness!r}")
  low = arg_checks.check_float("sharpness[0]", sharpness[0], above=0.0)
  arg_checks.check_float("sharpness[1]", sharpness[1], minimum=low)
  if len(grid) != 2:
    raise ValueError(f"grid must be (height, width), got {grid!r}")
  for name, value in zip(("grid[0]", "grid[1]"), grid, strict=True):
    arg_checks.check_int(name, value, minimum=1)
  rng = np.random.default_rng([int(seed), 39])
  dirs, weights = direction_grid(*grid)
  lights, kinds = [], []
  for _ in range(int(num_environments)):
    lights.append(environment_light(rng, n, dirs, weights, sharpness))
    kinds.append("environment")
  for _ in range(int(num_random)):
    lights.append(random_nonnegative_light(rng, n, dirs))
    kinds.append("random")
  lights = np.asarray(lights, np.float64).reshape(-1, n)
  lights *= power * UNIFORM_NORM / lights[:, :1]
  return lights, tuple(kinds)
