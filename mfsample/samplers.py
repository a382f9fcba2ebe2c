"""Manifold samplers: theta(z) = mean + B_hat z, every kind of B_hat in one place.

A stochastic model is a distribution over 3DGS parameters (paper Sec. 4.2, Eq. 7),

  theta(z) = mean + B_hat z,   z ~ U[-1, 1]^k,

whose B_hat (the paper's generating matrix) is described by a static, hashable
`SamplerSpec`. What differs between the kinds of B_hat is behaviour of the spec, defined here
and nowhere else:

| kind          | B_hat entry   | z              | z source        | covariance of theta        |
| ------------- | ------------- | -------------- | --------------- | -------------------------- |
| deterministic | none          | [0]            | none            | 0 (plain 3DGS)             |
| diagonal      | [C, ...]      | [C, D]         | uniform         | diagonal                   |
| block         | [C, ..., k]   | [C, k]         | uniform         | one rank-k block per Gaussian |
| lowrank       | [C, ..., k]   | [k]            | Sobol (default) | B_hat B_hat^T, rank k (Eq. 7) |

C is the capacity and D the number of stochastic entries per Gaussian (groups in
`groups.GROUP_ORDER` order, each flattened). z is uniform on [-1, 1]: for the low-rank
sampler a scrambled Sobol sequence (paper Sec. 4.3) unless the spec asks for uniforms; for
the per-Gaussian samplers pseudo-random uniforms (Sobol sequences stop at 21201 dimensions
and bring nothing at millions). `sample_z` is the one way to draw the z of U; a z outside
[-1, 1] (`Z_RANGE`, `z_in_range`) is refused by the functions of U, or makes their answer
NaN where traced.

A new kind is its maths (a z-shape function and an offsets function) and one `SamplerKind`
entry in `KINDS`: validators, configs, checkpoints, tables and the viewer read the registry.

B_hat is held as raw entries (`Params.b_hat`) with a fixed random sign each: B_hat =
relu(raw) * sign (paper Sec. 4.3; `signed_b_hat`), clamped into [0, bound] after every
optimiser step (`clamp_b_hat`). With z ~ U[-1, 1] (variance 1/3 per component), the
per-entry variance of theta is sum_j B_hat[:, j]^2 / 3 (`entry_variance`).

The functions below take any model with `params.mean`, `params.b_hat`, `signs` and `spec`
(`mfsample.model.Model`, the relightable field's too); `mfsample.model.sample` turns a
realisation into `Gaussians`.
"""

import dataclasses
import math
import warnings
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import arg_checks
from mfsample import settings_checks as sc
from mfsample.groups import GROUP_ORDER, ordered

# Dimensions of scipy's Sobol direction numbers (Joe and Kuo).
_SOBOL_MAX_DIM = 21201
Z_SOURCES = ("sobol", "uniform")
# Every kind draws z ~ U[-1, 1] entry by entry: the range of z (`z_in_range`).
Z_RANGE = (-1.0, 1.0)
# relu(raw) of B_hat is kept in [0, bound] (the authors' code): the centres' bound is in units
# of the scene extent; transfer matrices as SH colour (`mfsample.lighting`).
DEFAULT_BOUNDS = {"means": 1.0, "log_scales": 20.0, "quats": 2.0, "opacity_logits": 20.0,
                  "sh_dc": 0.5, "sh_rest": 0.5, "transfer_dc": 0.5, "transfer_rest": 0.5}


# ------------------------------------------------------------------ the kinds


def _no_z(rank, capacity, channels):
  return (0,)


def _shared_z(rank, capacity, channels):
  return (rank,)


def _block_z(rank, capacity, channels):
  return (capacity, rank)


def _entry_z(rank, capacity, channels):
  return (capacity, channels)


def _no_offsets(b_hat, z):
  return {}


def _lowrank_offsets(b_hat, z):
  """B_hat [C, ..., k] @ z [k]: k uniforms shared by the whole model."""
  return {g: b @ z for g, b in b_hat.items()}


def _block_offsets(b_hat, z):
  """One block of k columns per Gaussian: sum_j B_hat[c, ..., j] z[c, j]."""
  out = {}
  for g, b in b_hat.items():
    zc = z.reshape((z.shape[0],) + (1,) * (b.ndim - 2) + (z.shape[1],))
    out[g] = jnp.sum(b * zc, axis=-1)
  return out


def _diagonal_offsets(b_hat, z):
  """One uniform per entry: the groups' entries side by side along z's last axis."""
  out, offset = {}, 0
  for g, b in b_hat.items():
    size = math.prod(b.shape[1:])
    out[g] = b * z[:, offset:offset + size].reshape(b.shape)
    offset += size
  return out


@dataclasses.dataclass(frozen=True)
class SamplerKind:
  """What one kind of B_hat is: the properties every other module asks the spec, and its
  maths.

  Attributes:
    name: the kind's name in configs, records and checkpoints.
    stochastic: whether it has a B_hat at all.
    rank_axis: whether a B_hat entry carries a trailing axis of k columns.
    sobol: whether its z can be scrambled Sobol points (k dimensions at most 21201).
    covariance: the covariance of theta, for docs and tables.
    label: its name in tables ("Ours": the paper's low-rank B_hat).
    z_shape: (rank k, capacity C, stochastic entries per Gaussian D) -> the shape of one z.
    offsets: (B_hat {group: [C, ...]} in canonical group order, one z) -> {group: B_hat z}.
  """

  name: str
  stochastic: bool
  rank_axis: bool
  sobol: bool
  covariance: str
  label: str
  z_shape: Callable
  offsets: Callable

  @property
  def z_per_gaussian(self):
    """Whether z has a leading capacity axis [C] (Gaussians independent)."""
    return len(self.z_shape(1, 2, 3)) == 2


KINDS = {kind.name: kind for kind in (
    SamplerKind("deterministic", False, False, False, "0 (plain 3DGS)", "Deterministic",
                _no_z, _no_offsets),
    SamplerKind("diagonal", True, False, False, "diagonal", "Diagonal", _entry_z,
                _diagonal_offsets),
    SamplerKind("block", True, True, False, "block diagonal, one rank-k block per Gaussian",
                "Block", _block_z, _block_offsets),
    SamplerKind("lowrank", True, True, True, "B_hat B_hat^T, rank k (paper Eq. 7)", "Ours",
                _shared_z, _lowrank_offsets),
)}
# The kinds of B_hat (`SamplerSpec.kind`): the one definition every validator reads.
SAMPLER_KINDS = tuple(KINDS)
STOCHASTIC_KINDS = tuple(name for name, kind in KINDS.items() if kind.stochastic)


@dataclasses.dataclass(frozen=True)
class SamplerSpec:
  """Static description of B_hat (hashable: part of the jit cache key).

  Attributes:
    kind: one of `SAMPLER_KINDS` (module docstring): "deterministic" (no B_hat, plain 3DGS),
      "diagonal" (one independent uniform per parameter entry), "block" (k uniforms per
      Gaussian: Gaussians independent, the entries of one Gaussian correlated) or "lowrank"
      (k uniforms shared by the whole model; paper Eq. 7).
    rank: k, columns of B_hat per entry (lowrank and block; ignored otherwise).
    groups: the stochastic parameter groups (a subset of the model's groups); the others are
      deterministic.
    bounds: ((group, upper bound), ...): relu(raw) is kept in [0, bound] (authors' code: raw
      entries are clamped after every step).
    z: "sobol" (scrambled Sobol points where the kind allows them: low rank; the paper's) or
      "uniform" (pseudo-random uniforms); the per-Gaussian kinds always draw uniforms.
  """

  kind: str = "lowrank"
  rank: int = 2
  groups: tuple = ()
  bounds: tuple = ()
  z: str = "sobol"

  def __post_init__(self):
    sc.check_choice("SamplerSpec.kind", self.kind, SAMPLER_KINDS)
    sc.check_int("SamplerSpec.rank", self.rank, minimum=1)
    sc.check_choice("SamplerSpec.z", self.z, Z_SOURCES)
    # Tuples: the spec is a static, hashable jit argument.
    if not isinstance(self.groups, tuple):
      raise sc.SettingsError("SamplerSpec.groups", self.groups, "a tuple of group names")
    sc.check_names("SamplerSpec.groups", self.groups, GROUP_ORDER)
    if not isinstance(self.bounds, tuple) or not all(isinstance(b, tuple) for b in self.bounds):
      raise sc.SettingsError("SamplerSpec.bounds", self.bounds, "a tuple of (group, bound) "
                             "pairs")
    # A bound of 0, a negative one or NaN would clamp B_hat to 0 (or NaN) after the first
    # step: a model trained silently into a deterministic one.
    sc.check_table("SamplerSpec.bounds", self.bounds, GROUP_ORDER, above=0.0)
    missing = set(self.groups) - {g for g, _ in self.bounds}
    if self.behaviour.stochastic and missing:
      raise sc.SettingsError("SamplerSpec.bounds", self.bounds,
                             f"a bound for every stochastic group (no bound given for "
                             f"{sorted(missing)})")

  @classmethod
  def default(cls, groups, *, extent=1.0, kind="lowrank", rank=2, z="sobol"):
    """The training job's spec for stochastic `groups` in a scene of `extent` (world
    units): `DEFAULT_BOUNDS`, the centres' times the extent."""
    extent = arg_checks.check_float("extent", extent, above=0.0)
    groups = tuple(groups)
    return cls(kind=kind, rank=rank, groups=groups, z=z, bounds=tuple(
        (g, DEFAULT_BOUNDS[g] * (extent if g == "means" else 1.0)) for g in groups
        if g in DEFAULT_BOUNDS))

  @property
  def behaviour(self) -> SamplerKind:
    """The `SamplerKind` of `kind`."""
    return KINDS[self.kind]

  @property
  def stochastic(self):
    """Whether samples differ: a stochastic kind with at least one stochastic group."""
    return self.behaviour.stochastic and bool(self.groups)

  @property
  def columns(self):
    """Trailing axis of a B_hat entry: (k,) for the kinds with a rank axis, () otherwise."""
    return (self.rank,) if self.behaviour.rank_axis else ()

  @property
  def z_source(self):
    """Where z comes from: "sobol", "uniform", or "none" (no stochastic entry)."""
    if not self.stochastic:
      return "none"
    return "sobol" if self.behaviour.sobol and self.z == "sobol" else "uniform"

  def bound(self, group):
    return dict(self.bounds)[group]

  def to_dict(self):
    """A JSON-able record of the spec (checkpoints, exported records)."""
    return {"kind": self.kind, "rank": int(self.rank), "groups": list(self.groups),
            "bounds": [[g, float(b)] for g, b in self.bounds], "z": self.z}

  @classmethod
  def from_dict(cls, record):
    """The spec of a `to_dict` record (ValueError naming what is wrong with it)."""
    if not isinstance(record, dict):
      raise ValueError(f"a sampler record must be a JSON object, got {type(record).__name__}")
    try:
      return cls(kind=str(record["kind"]), rank=int(record["rank"]),
                 groups=tuple(str(g) for g in record["groups"]),
                 bounds=tuple((str(g), float(b)) for g, b in record["bounds"]),
                 z=str(record.get("z", "sobol")))
    except (KeyError, TypeError) as e:
      raise ValueError(f"a sampler record needs kind, rank, groups and bounds ({e})") from e


# ------------------------------------------------------------------ B_hat


def b_hat_magnitude(raw):
  """`|B_hat| = relu(raw)`, per group: the one activation of B_hat's entries.

  The relu takes gradient 1 at raw = 0 (`x >= 0`, not `x > 0`): the clamp after each
  optimiser step parks entries at exactly 0, and the volume term must be able to lift them
  again (the authors clamp raw values in place, which has the same effect).
  """
  return {g: jnp.where(v >= 0, v, 0.0) for g, v in raw.items()}


def signed_b_hat(raw, signs):
  """B_hat = relu(raw) * sign, per group (paper Sec. 4.3), in canonical group order."""
  magnitude = b_hat_magnitude(raw)
  return {g: magnitude[g] * signs[g].astype(magnitude[g].dtype) for g in ordered(magnitude)}


def clamp_b_hat(raw, spec: SamplerSpec):
  """Clamps raw B_hat entries into [0, bound] (after every optimiser step)."""
  return {g: jnp.clip(v, 0.0, spec.bound(g)) for g, v in raw.items()}


# ------------------------------------------------------------------ theta(z)


def channels_per_gaussian(model):
  """D: stochastic entries per Gaussian (the trailing axis of a diagonal z)."""
  cols = len(model.spec.columns)
  return sum(math.prod(v.shape[1:v.ndim - cols]) for v in model.params.b_hat.values())


def z_shape(model):
  """The shape of one z for `mfsample.model.sample(model, z)` (module docstring)."""
  spec = model.spec
  if not spec.stochastic:
    return (0,)
  return spec.behaviour.z_shape(spec.rank, model.capacity, channels_per_gaussian(model))


def perturb(model, z):
  """Raw parameters of the realisation theta(z) = mean + B_hat z.

  Args:
    model: a model (module docstring).
    z: one z of shape `z_shape(model)`, entries in [-1, 1].

  Returns:
    {group: [C, ...]} raw parameters (deterministic groups are the mean's arrays).
  """
  spec = model.spec
  mean = model.params.mean
  if not spec.stochastic:
    return dict(mean)
  z = jnp.asarray(z, mean["means"].dtype)
  if z.shape != z_shape(model):
    raise ValueError(f"z must have shape {z_shape(model)} for the {spec.kind} sampler, "
                     f"got {z.shape}")
  deltas = spec.behaviour.offsets(signed_b_hat(model.params.b_hat, model.signs), z)
  return {g: (v + deltas[g] if g in deltas else v) for g, v in mean.items()}


def z_in_range(z):
  """Scalar bool (jnp, usable under jit): every entry of `z` lies in `Z_RANGE` (a NaN does
  not). z outside it scales B_hat's spread: U of a z of 3 is 9 times U of one of 1."""
  return jnp.all((z >= Z_RANGE[0]) & (z <= Z_RANGE[1]))


def entry_variance(model):
  """{group: [C, ...]} per-entry variance of theta for z ~ U[-1, 1]: sum_j B_hat_j^2 / 3."""
  b_hat = signed_b_hat(model.params.b_hat, model.signs)
  cols = len(model.spec.columns)
  return {g: (jnp.sum(b * b, axis=-1) if cols else b * b) / 3.0 for g, b in b_hat.items()}


# ------------------------------------------------------------------ z


def sobol_z(num, dim, seed, offset=0):
  """Points `offset .. offset + num - 1` of a scrambled Sobol sequence, mapped to [-1, 1].

  Deterministic in (dim, seed): a resumed run regenerates exactly the same points.

  Args:
    num: number of points.
    dim: dimension k (1 <= k <= 21201).
    seed: scrambling seed.
    offset: index of the first point.

  Returns:
    [num, dim] float32 numpy array in [-1, 1].
  """
  from scipy.stats import qmc  # host-only dependency, imported where used
  for name, value, low in (("num", num, 0), ("dim", dim, 0), ("offset", offset, 0)):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
      raise ValueError(f"sobol_z: {name} must be an integer >= {low}, got {value!r}")
  arg_checks.check_seed("sobol_z: seed", seed)
  if dim > _SOBOL_MAX_DIM:
    raise ValueError(f"sobol_z: dim = {dim} exceeds the {_SOBOL_MAX_DIM} dimensions of the "
                     "Sobol direction numbers (use uniform z instead)")
  if dim < 1:
    return np.zeros((num, 0), np.float32)
  engine = qmc.Sobol(d=dim, scramble=True, seed=seed)
  if offset:
    engine.fast_forward(offset)
  with warnings.catch_warnings():
    # Balance properties need powers of two; for a sequence consumed step by step we
    # accept the warning's premise.
    warnings.simplefilter("ignore", UserWarning)
    points = engine.random(num)
  return (2.0 * points - 1.0).astype(np.float32)


def sample_z(model: "mfsample.model.Model", num_samples: int, *,  # noqa: F821
             seed: int = 0) -> jax.Array:
  """z `[M, *z_shape(model)]` of M = `num_samples` samples: the one way to draw the z of U.

  The first M points of the scrambled Sobol sequence of `seed` where the spec's z source is
  Sobol (the low-rank sampler; paper Sec. 4.4: the first two are nearly antithetic), else M
  pseudo-random uniforms on [-1, 1] from `jax.random.PRNGKey(seed)`; zero-size rows for a
  deterministic model. The same (model shapes, M, seed) always give the same z.

  Args:
    model: a model (only its spec and shapes are used).
    num_samples: M >= 1 (U needs M >= 2 to be non-zero).
    seed: integer seed (Sobol scrambling, or the uniforms' key).

  Returns:
    `[M, *z_shape(model)]` array of the model's dtype, entries in [-1, 1].
  """
  arg_checks.check_int("num_samples", num_samples, minimum=1)
  arg_checks.check_seed("seed", seed)
  dtype = model.params.mean["means"].dtype
  if model.spec.z_source == "sobol":
    return jnp.asarray(sobol_z(int(num_samples), model.spec.rank, seed), dtype)
  return jax.random.uniform(jax.random.PRNGKey(seed), (int(num_samples),) + z_shape(model),
                            dtype, minval=-1.0, maxval=1.0)


def sobol_rows(spec: SamplerSpec, count, seed):
  """[count, k] scrambled Sobol z rows (a training run's, step after step) where the spec's z
  source is Sobol, else an empty [count, 0] (the step then draws uniforms from its key)."""
  if spec.z_source == "sobol":
    return sobol_z(int(count), spec.rank, int(seed))
  return np.zeros((int(count), 0), np.float32)


def draw_z(model, num_samples, key, rows):
  """M z's inside jit: the Sobol `rows` [M, k] where the spec's z source is Sobol, else
  uniforms on [-1, 1] from `key` (what a training step renders)."""
  shape = (num_samples,) + z_shape(model)
  dtype = model.params.mean["means"].dtype
  if model.spec.z_source == "sobol":
    arg_checks.check_shape("rows", rows, shape, "Sobol rows of the step")
    return jnp.asarray(rows, dtype).reshape(shape)
  return jax.random.uniform(key, shape, dtype, minval=-1.0, maxval=1.0)
