"""The stochastic Gaussian field: raw parameters, capacity and mask, the one activation.

A model is a distribution over 3DGS parameters (paper Sec. 4.2, Eq. 7):

  theta(z) = mean + B_hat z,   z ~ U[-1, 1]^k,

held as *raw*, unconstrained arrays grouped by meaning (the 3DGS parameterisation: centres,
log-scales, unnormalised quaternions, opacity logits, SH coefficients). B_hat (the paper's
generating matrix) is parameterised per group as relu(raw) * sign with a fixed random sign per
entry (paper Sec. 4.3), so its columns point in diverse directions. Samples perturb the raw
parameters; `activate` (the only place where constraints are applied) turns raw values into
the renderer's `Gaussians`.

`sample(model, z)` is the realisation theta(z) as `Gaussians`; the kinds of B_hat, z and the
perturbation are `mfsample.samplers`'.

Shapes are static: every array has a leading *capacity* axis C, and `mask` marks the live
rows. Capacity grows on the host in buckets (`capacity_bucket`), never inside jit.

Validity (as `mfsample.camera`'s): a model is valid when every raw parameter of its live
Gaussians is finite and every B_hat entry is finite and at most its bound. `Model.valid` is
the test as a jnp flag (jitted code makes its answer NaN where it is False),
`problems()` / `validate()` name the field, group and Gaussian, and `check_model` is the
check every public function that takes a model makes (`mfsample.arg_checks`' rule).

Groups are a dict so that a later variant (a relightable field's transfer matrices) adds a
group without touching the samplers: every group is an array [C, ...] and the samplers
treat them alike.
"""

import functools
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks, numerics
from mfsample._pytree import pytree_dataclass, replace, static_field
from mfsample.gaussians import Gaussians
from mfsample.groups import GROUP_ORDER, ordered
from mfsample.samplers import SamplerSpec, perturb

# Log-scales are clamped to this range before exp: far beyond any real Gaussian (e^10 world
# units), it keeps samples finite even when B_hat sits at its bounds with many columns
# (rank 64 x bound 20 would overflow float32's exp).
LOG_SCALE_RANGE = (-30.0, 10.0)

# Neutral values for padding rows: finite, and harmless even if a mask were dropped
# (opacity sigmoid(-20) ~ 2e-9 is below any alpha threshold).
_PAD_OPACITY_LOGIT = -20.0


class InvalidModelError(ValueError):
  """A model with a non-finite parameter, or a B_hat entry above its bound."""


class Params(NamedTuple):
  """The trainable arrays (what the optimiser sees).

  Attributes:
    mean: {group: [C, ...]} raw 3DGS parameters, the mean of the distribution.
    b_hat: {group: [C, ..., k] (lowrank, block) or [C, ...] (diagonal)} raw entries of
      B_hat for the stochastic groups (B_hat = relu(raw) * sign,
      `mfsample.samplers.signed_b_hat`); empty for the deterministic sampler.
  """

  mean: dict
  b_hat: dict


@pytree_dataclass
class Model:
  """A stochastic 3DGS model with a fixed capacity C.

  Attributes:
    params: `Params` (trainable).
    signs: {group: int8 array shaped like params.b_hat[group]}: the fixed +-1 of B_hat.
    mask: [C] bool, True on live Gaussians.
    sh_degree: int32 scalar, the active SH degree (the 3DGS schedule raises it during
      training); higher bands are zeroed by `activate`, so shapes never change.
    spec: `SamplerSpec` (static).
  """

  params: Params
  signs: dict
  mask: chex.Array
  sh_degree: chex.Array
  spec: SamplerSpec = static_field()

  @property
  def capacity(self):
    return self.mask.shape[0]

  @property
  def max_sh_degree(self):
    rest = self.params.mean.get("sh_rest")
    return 0 if rest is None else int(np.sqrt(rest.shape[1] + 1)) - 1

  @property
  def num_live(self):
    """Number of live Gaussians (host int; syncs)."""
    return int(np.sum(np.asarray(self.mask)))

  def replace(self, **changes):
    return replace(self, **changes)

  # ---------------------------------------------------------------- validity

  @property
  def valid(self):
    """Scalar bool: every raw parameter of every live Gaussian is finite, and every raw
    B_hat entry of a live Gaussian is finite and at most its bound (`SamplerSpec.bounds`:
    training keeps relu(raw) in [0, bound]).

    Pure jnp, so it works under jit / vmap / grad. The renderer culls a Gaussian with a
    non-finite parameter, so without this test a broken model renders, and its U comes
    out finite (0 when every sample is culled alike).
    """
    live = self.mask

    def rows(ok):
      return jnp.all(jnp.all(ok.reshape(ok.shape[0], -1), axis=-1) | ~live)

    ok = [rows(jnp.isfinite(v)) for v in self.params.mean.values()]
    for g, v in self.params.b_hat.items():
      # In the entries' dtype: the training clamp rounds the bound the same way.
      ok.append(rows(jnp.isfinite(v) & (v <= jnp.asarray(self.spec.bound(g), v.dtype))))
    return functools.reduce(jnp.logical_and, ok, jnp.asarray(True))

  def problems(self):
    """What makes this (concrete) model invalid (`valid`): a list of messages naming the
    field, the group and the first Gaussian, empty when valid. Host numpy: it syncs."""
    live = np.asarray(self.mask, bool)
    num_live = int(live.sum())
    out = []
    for kind, groups in (("mean", self.params.mean), ("b_hat", self.params.b_hat)):
      for g in ordered(groups):
        values = np.asarray(groups[g])
        rows = values.reshape(values.shape[0], -1)
        bad = ~np.all(np.isfinite(rows), axis=-1) & live
        field = f"model.params.{kind}[{g!r}]"
        if np.any(bad):
          i = int(np.argmax(bad))
          out.append(f"{field}[{i}] (Gaussian {i}) is not finite ({int(bad.sum())} of "
                     f"{num_live} live Gaussians)")
          continue
        if kind == "b_hat":
          bound = np.asarray(self.spec.bound(g), values.dtype)
          above = np.any(rows > bound, axis=-1) & live
          if np.any(above):
            i = int(np.argmax(above))
            out.append(f"{field}[{i}] (Gaussian {i}) reaches {float(np.max(rows[i])):g}, above "
                       f"its bound {float(bound):g} (SamplerSpec.bounds; training keeps B_hat "
                       f"in [0, bound]; {int(above.sum())} of {num_live} live Gaussians)")
    return out

  def validate(self):
    """Raises `InvalidModelError` listing `problems()`; returns the model when valid."""
    problems = self.problems()
    if problems:
      raise InvalidModelError("invalid model: " + "; ".join(problems) + ".")
    return self


_valid = jax.jit(lambda model: model.valid)


def check_model(model, *, sync=False, name="model"):
  """The check every public function that takes a model makes (`mfsample.arg_checks`'s rule).

  Always: `model` is a `Model` (else ValueError naming `name`). Its values (`Model.valid`)
  are checked when concrete: on the host, or on the device with `sync` (for functions that
  synchronise anyway; one flag is fetched, the arrays only when it is False). A bad model
  raises `InvalidModelError` naming the field, the group and the Gaussian. Traced, or on the
  device without `sync`, nothing is checked here: the function's jitted part makes its
  answer NaN where `model.valid` is False (`nan_unless`).

  Returns:
    `model`.
  """
  if not isinstance(model, Model):
    raise ValueError(f"{name} must be a mfsample.Model, got {type(model).__name__}")
  if arg_checks.is_traced(model):
    return model
  on_device = any(isinstance(leaf, jax.Array) for leaf in jax.tree.leaves(model))
  if on_device and not sync:
    return model
  if not arg_checks.concrete_bool(_valid, model):
    model.validate()
  return model


def group_shapes(sh_degree):
  """{group: per-Gaussian trailing shape} of a model with SH degree `sh_degree`."""
  shapes = {"means": (3,), "log_scales": (3,), "quats": (4,), "opacity_logits": (),
            "sh_dc": (3,)}
  if sh_degree > 0:
    shapes["sh_rest"] = ((sh_degree + 1) ** 2 - 1, 3)
  return shapes


def model_group_shapes(model):
  """{group: per-Gaussian trailing shape} of the groups `model` holds (any kind of model)."""
  return {g: tuple(v.shape[1:]) for g, v in model.params.mean.items()}


def capacity_bucket(n, minimum=256):
  """The smallest size >= n of the form 2^j or 3 * 2^(j-1) (growth by 1.33x-1.5x).

  Few distinct capacities means few recompilations of the jitted step.
  """
  size = 1 << max(int(minimum) - 1, 1).bit_length()  # a power of two >= 2
  while size < n:
    size = size * 3 // 2 if size & (size - 1) == 0 else size * 4 // 3
  return size


# ------------------------------------------------------------------------- activation


def activate(mean, mask, sh_degree):
  """Raw parameters -> `Gaussians` (the one place where constraints are applied).

  scale = exp(clip(log_scale, LOG_SCALE_RANGE)), opacity = sigmoid(logit), quaternions
  unnormalised (the renderer normalises), SH = [DC, rest] with bands above `sh_degree` zeroed
  (shape-static schedule).

  Args:
    mean: {group: [C, ...]} raw parameters (a sample or the mean).
    mask: [C] bool.
    sh_degree: int scalar (may be traced), the active SH degree.

  Returns:
    `Gaussians` with C entries and `mask`.
  """
  sh = mean["sh_dc"][:, None, :]
  if "sh_rest" in mean:
    sh = jnp.concatenate([sh, mean["sh_rest"]], axis=1)
    k = jnp.arange(sh.shape[1])
    band = jnp.floor(jnp.sqrt(k.astype(jnp.float32)) + 1e-3).astype(jnp.int32)  # k -> l
    sh = jnp.where((band <= sh_degree)[None, :, None], sh, 0.0)
  return Gaussians(
      means=mean["means"],
      scales=jnp.exp(jnp.clip(mean["log_scales"], *LOG_SCALE_RANGE)),
      quats=mean["quats"],
      opacities=jax.nn.sigmoid(mean["opacity_logits"]),
      sh=sh,
      mask=mask,
  )


def mean_gaussians(model: "Model") -> Gaussians:
  """The mean model's `Gaussians` (what evaluation and export use)."""
  return activate(model.params.mean, model.mask, model.sh_degree)


def sample(model: "Model", z: jax.Array) -> Gaussians:
  """`Gaussians` of the realisation theta(z) = mean + B_hat z (paper Eq. 7; z of shape
  `mfsample.samplers.z_shape(model)`). Vmap over z for M samples."""
  return activate(perturb(model, z), model.mask, model.sh_degree)


# ------------------------------------------------------------------------- construction


def host_rng(key):
  """A numpy Generator seeded by a JAX PRNG key.

  Construction and densification run on the host with numpy: they have a new shape at
  every call, and eager JAX random ops would compile for each of them.
  """
  arg_checks.check_key(key)
  data = np.asarray(jax.random.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key)
                    else key, np.uint32)
  return np.random.default_rng(data.ravel().tolist())


def init_b_hat(rng, num, shapes, spec, init_scales, dtype=np.float32):
  """Fresh B_hat entries for `num` Gaussians: raw ~ scale * U[0, 1], random signs.

  Args:
    rng: `np.random.Generator` (see `host_rng`).
    num: number of rows.
    shapes: {group: per-Gaussian shape} of the model (stochastic groups it lacks are skipped).
    spec: `SamplerSpec`.
    init_scales: {group: float} multiplier of U[0, 1] (the authors' code: 1e-3, times the scene
      extent for centres and log-scales).

  Returns:
    (b_hat {group: [num, ..., k]}, signs {group: int8 same shape}) as numpy arrays; empty
    for the deterministic sampler. Entries are clamped to the spec's bounds, as after
    every training step: an init scale above a bound gives entries at the bound.
  """
  b_hat, signs = {}, {}
  if not spec.stochastic:
    return b_hat, signs
  for g in sorted(set(spec.groups) & set(shapes), key=GROUP_ORDER.index):
    shape = (num,) + tuple(shapes[g]) + spec.columns
    raw = (init_scales[g] * rng.random(shape)).astype(dtype)
    b_hat[g] = np.minimum(raw, np.asarray(spec.bound(g), dtype))
    signs[g] = np.where(rng.random(shape) < 0.5, 1, -1).astype(np.int8)
  return b_hat, signs


def padding_values(shapes, num, dtype=np.float32):
  """Neutral raw values for `num` padding rows (identity rotation, ~zero opacity), numpy."""
  out = {g: np.zeros((num,) + tuple(s), dtype) for g, s in shapes.items()}
  out["quats"][:, 0] = 1.0
  out["opacity_logits"][:] = _PAD_OPACITY_LOGIT
  return out


def _pad(x, capacity, fill):
  return np.concatenate([x, fill[: capacity - x.shape[0]].astype(x.dtype)], axis=0)


def init_model(key: jax.Array, points: np.ndarray, *, spec: SamplerSpec, sh_degree: int,
               init_scales: dict, capacity: int | None = None, init_opacity: float = 0.1,
               colors: np.ndarray | None = None) -> "Model":
  """A model whose mean Gaussians sit at `points` (3DGS initialisation), float32.

  Scales follow 3DGS: the root mean squared distance to the 3 nearest neighbours (isotropic),
  identity rotations, opacity `init_opacity`; colours near grey unless `colors` is given
  (3DGS's random initialisation uses SH DC ~ U[0, 1/255]).

  Args:
    key: PRNG key (colours, B_hat entries and signs).
    points: [N, 3] initial centres (host array), N >= 1, finite and within
      `mfsample.numerics.WORLD_LIMIT` (1e18) of the origin.
    spec: `SamplerSpec`.
    sh_degree: maximum SH degree (0..3); no SH-rest arrays when 0.
    init_scales: {group: float} see `init_b_hat` (entries are clamped to the spec's bounds).
    capacity: C >= N (default `capacity_bucket(N)`).
    init_opacity: initial opacity in (0, 1).
    colors: optional [N, 3] RGB in [0, 1].

  Returns:
    `Model` with the first N rows live and `sh_degree` (active) 0.
  """
  points, capacity = check_initial(points, capacity, init_opacity)
  n = len(points)
  if isinstance(sh_degree, bool) or not isinstance(sh_degree, (int, np.integer)) or not (
      0 <= sh_degree <= 3):
    raise ValueError(f"sh_degree must be an integer in 0..3, got {sh_degree!r}")
  shapes = group_shapes(sh_degree)
  check_init_scales(init_scales, spec, shapes)
  rng = host_rng(key)
  if colors is None:
    sh_dc = rng.random((n, 3)) / 255.0
  else:
    colors = _check_colors(colors, n)
    sh_dc = (colors - 0.5) / 0.28209479177387814  # rgb_to_sh_dc
  quats = np.zeros((n, 4))
  quats[:, 0] = 1.0
  mean = {
      "means": points,
      "log_scales": np.repeat(np.log(knn_scale(points))[:, None], 3, 1),
      "quats": quats,
      "opacity_logits": np.full((n,), np.log(init_opacity / (1 - init_opacity))),
      "sh_dc": sh_dc,
  }
  if "sh_rest" in shapes:
    mean["sh_rest"] = np.zeros((n,) + shapes["sh_rest"])
  pad = padding_values(shapes, capacity - n)
  mean = {g: jnp.asarray(_pad(v.astype(np.float32), capacity, pad[g])) for g, v in mean.items()}
  b_hat, signs = init_b_hat(rng, n, shapes, spec, init_scales)
  zeros = lambda x: np.zeros((capacity,) + x.shape[1:], x.dtype)
  b_hat = {g: jnp.asarray(_pad(v, capacity, zeros(v))) for g, v in b_hat.items()}
  signs = {g: jnp.asarray(_pad(v, capacity, zeros(v))) for g, v in signs.items()}
  mask = jnp.asarray(np.arange(capacity) < n)
  return Model(Params(mean, b_hat), signs, mask, jnp.asarray(0, jnp.int32), spec)


def model_from_mean(key, mean, *, spec, init_scales, capacity=None):
  """A model whose mean is the raw parameters `mean` of a trained 3DGS model, float32.

  The Gaussians are kept exactly as given; B_hat starts as in `init_model` (small random
  entries, fresh signs), ready to be fitted with the mean frozen
  (`mfsample.train.posthoc.fit_b_hat`). The active SH degree is the full degree of `mean`:
  a trained model uses every band it has.

  Args:
    key: PRNG key (B_hat entries and signs).
    mean: {group: [N, ...]} raw parameters of every group of `group_shapes(degree)` (e.g.
      `mfsample.data.ply.load_ply`), N >= 1: finite in float32, centres within
      `mfsample.numerics.WORLD_LIMIT` (1e18) of the origin.
    spec: `SamplerSpec`.
    init_scales: {group: float} see `init_b_hat` (entries are clamped to the spec's bounds).
    capacity: C >= N (default `capacity_bucket(N)`).

  Returns:
    `Model` with the first N rows live.
  """
  rest = mean.get("sh_rest")
  sh_degree = 0 if rest is None else int(round(np.sqrt(np.shape(rest)[1] + 1))) - 1
  shapes = group_shapes(sh_degree)
  if set(mean) != set(shapes):
    raise ValueError(f"mean must hold exactly the groups {sorted(shapes)}, got {sorted(mean)}")
  n = len(mean["means"])
  for g, shape in shapes.items():
    if tuple(np.shape(mean[g])) != (n,) + tuple(shape):
      raise ValueError(f"mean[{g!r}] must have shape {[n, *shape]}, got "
                       f"{list(np.shape(mean[g]))}")
  if n < 1:
    raise ValueError("mean holds no Gaussians")
  for g in shapes:
    _check_finite_rows(f"mean[{g!r}]", np.asarray(mean[g], np.float64).reshape(n, -1),
                       limit=numerics.WORLD_LIMIT if g == "means" else _FLOAT32_MAX)
  capacity = capacity_bucket(n) if capacity is None else arg_checks.check_int(
      "capacity", capacity, minimum=1)
  if capacity < n:
    raise ValueError(f"capacity {capacity} < number of Gaussians {n}")
  check_init_scales(init_scales, spec, shapes)
  pad = padding_values(shapes, capacity - n)
  params = {g: jnp.asarray(_pad(np.asarray(v, np.float32), capacity, pad[g]))
            for g, v in mean.items()}
  b_hat, signs = init_b_hat(host_rng(key), n, shapes, spec, init_scales)
  zeros = lambda x: np.zeros((capacity,) + x.shape[1:], x.dtype)
  b_hat = {g: jnp.asarray(_pad(v, capacity, zeros(v))) for g, v in b_hat.items()}
  signs = {g: jnp.asarray(_pad(v, capacity, zeros(v))) for g, v in signs.items()}
  mask = jnp.asarray(np.arange(capacity) < n)
  return Model(Params(params, b_hat), signs, mask, jnp.asarray(sh_degree, jnp.int32), spec)


def check_initial(points, capacity, init_opacity):
  """(points [N, 3] float64, capacity C >= N) after checking the arguments that `init_model`
  and `mfsample.lighting.init_relightable` share; ValueError naming the argument (and row)."""
  arg_checks.check_real_dtype("points", points)
  points = np.asarray(points, np.float64)
  if points.ndim != 2 or points.shape[1] != 3 or len(points) < 1:
    raise ValueError(f"points must have shape [N >= 1, 3], got {points.shape}")
  _check_finite_rows("points", points, limit=numerics.WORLD_LIMIT)
  n = len(points)
  if capacity is None:
    capacity = capacity_bucket(n)
  capacity = arg_checks.check_int("capacity", capacity, minimum=1)
  if capacity < n:
    raise ValueError(f"capacity {capacity} < number of points {n}")
  arg_checks.check_float("init_opacity", init_opacity, above=0.0, below=1.0)  # a finite logit
  return points, capacity


def check_init_scales(init_scales, spec, shapes):
  """ValueError unless `init_scales` gives a finite number >= 0 for every stochastic group."""
  if not spec.stochastic:
    return
  for g in sorted(set(spec.groups) & set(shapes), key=GROUP_ORDER.index):
    scale = init_scales.get(g) if hasattr(init_scales, "get") else None
    ok = isinstance(scale, (int, float, np.integer, np.floating)) and not isinstance(scale, bool)
    if not ok or not np.isfinite(scale) or scale < 0:
      raise ValueError(f"init_scales[{g!r}] must be a finite number >= 0 (stochastic group), "
                       f"got {scale!r}")


def _check_colors(colors, n):
  """[N, 3] float64 RGB in [0, 1]. Integer colours (uint8 0..255) are refused rather than
  guessed: read as [0, 1] values they would become SH coefficients in the hundreds."""
  arg_checks.check_real_dtype("colors", colors)
  dtype = np.asarray(colors).dtype
  if not np.issubdtype(dtype, np.floating):
    raise ValueError(f"colors must be floats in [0, 1], got dtype {dtype} (for 8-bit colours "
                     "pass colors / 255)")
  colors = np.asarray(colors, np.float64)
  if colors.shape != (n, 3):
    raise ValueError(f"colors must have shape [N={n}, 3], got {colors.shape}")
  _check_finite_rows("colors", colors)
  outside = np.any((colors < 0.0) | (colors > 1.0), axis=-1)
  if np.any(outside):
    i = int(np.argmax(outside))
    raise ValueError(f"colors[{i}] = {colors[i].tolist()} is outside [0, 1] "
                     f"({int(outside.sum())} row(s))")
  return colors


_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _check_finite_rows(name, x, limit=None):
  """ValueError naming `name` and the first row with a non-finite entry, or (with `limit`)
  one of magnitude above `limit`: models are float32, so a finite float64 of 1e39 would
  become inf there."""
  bad = ~np.all(np.isfinite(x), axis=-1)
  if np.any(bad):
    raise ValueError(f"{name}[{int(np.argmax(bad))}] is not finite ({int(bad.sum())} row(s) "
                     "with NaN or inf)")
  if limit is not None:
    far = np.any(np.abs(x) > limit, axis=-1)
    if np.any(far):
      i = int(np.argmax(far))
      raise ValueError(f"{name}[{i}] = {np.asarray(x[i]).tolist()} is out of range: "
                       f"magnitudes must be at most {limit:g} ({int(far.sum())} row(s) beyond; "
                       + ("world coordinates beyond it overflow float32's squares)"
                          if limit == numerics.WORLD_LIMIT else "the model is float32)"))


def knn_scale(points, k=3):
  """[N] root mean squared distance to the k nearest other points (3DGS scale init)."""
  points = np.asarray(points, np.float64)
  n = len(points)
  if n < 2:
    return np.full((n,), 0.01)
  from scipy.spatial import cKDTree  # host-only dependency, imported where used
  kk = min(k, n - 1)
  dist, _ = cKDTree(points).query(points, k=kk + 1)
  d2 = np.mean(np.square(dist[:, 1:]), axis=1)
  return np.sqrt(np.maximum(d2, 1e-7))
