"""Checks of the public functions' arguments: eager on concrete values, NaN when traced.

The convention of the whole API (`mfsample.camera` is the model):

* Shapes, dtypes and counts are static, also under `jit`: they are checked always, and a bad
  one raises a `ValueError` naming the argument.
* Values (finiteness, ranges) are checked when they are on the host (numpy arrays, Python
  numbers), once per call. A JAX array is not fetched from the device to be checked (that
  would synchronise every call of a hot loop) unless the function syncs anyway, and under
  `jit`, `vmap` or `grad` a value cannot raise: there, a function whose answer a bad value
  would make silently finite and wrong returns NaN instead (`nan_unless`), which every
  finiteness check downstream catches.

Messages read "`name` must be ..., got ...", with the first offending index for arrays.
"""

from numbers import Integral, Real

import jax
import jax.numpy as jnp
import numpy as np


def is_traced(*trees):
  """Whether any leaf of `trees` is a tracer (inside `jit`, `vmap` or `grad`)."""
  return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(trees))


def check_int(name, value, *, minimum=None, maximum=None):
  """`value` as an int; ValueError naming `name` unless it is an integer in range (a bool or
  a float such as 2.5 or 2.0 is refused: counts and sizes are integers)."""
  ok = isinstance(value, Integral) and not isinstance(value, bool)
  ok = ok and (minimum is None or value >= minimum) and (maximum is None or value <= maximum)
  if not ok:
    raise ValueError(f"{name} must be an integer{_interval(minimum, maximum, None, None)}, "
                     f"got {value!r}")
  return int(value)


def check_float(name, value, *, minimum=None, maximum=None, above=None, below=None):
  """`value` as a float; ValueError naming `name` unless it is a finite real number with
  minimum <= value <= maximum and above < value < below (bools are refused)."""
  try:
    number = float(value) if _is_real(value) else None
  except TypeError:
    number = None
  ok = number is not None and np.isfinite(number)
  ok = ok and (minimum is None or number >= minimum) and (maximum is None or number <= maximum)
  ok = ok and (above is None or number > above) and (below is None or number < below)
  if not ok:
    raise ValueError(f"{name} must be a finite number{_interval(minimum, maximum, above, below)}"
                     f", got {value!r}")
  return number


def check_key(key, name="key"):
  """A JAX PRNG key (`jax.random.key(s)` or `jax.random.PRNGKey(s)`); ValueError otherwise.

  A plain integer seed is refused rather than silently seeded: every random function of the
  API takes the key as its explicit source of randomness.
  """
  dtype = getattr(key, "dtype", None)
  if dtype is not None and jnp.issubdtype(dtype, jax.dtypes.prng_key):
    if tuple(key.shape) == ():
      return key
  elif dtype is not None and tuple(np.shape(key)) == (2,) and np.dtype(dtype) == np.uint32:
    return key
  raise ValueError(f"{name} must be one JAX PRNG key (jax.random.key(seed) or "
                   f"jax.random.PRNGKey(seed)), got {_describe(key)}")


def check_seed(name, value):
  """A seed for numpy / scipy generators: an integer in [0, 2^63)."""
  return check_int(name, value, minimum=0, maximum=2 ** 63 - 1)


def first_non_finite(x):
  """Index (a tuple) of the first non-finite entry of the numpy array `x`, or None."""
  bad = ~np.isfinite(x)
  return tuple(int(i) for i in np.argwhere(bad)[0]) if np.any(bad) else None


def check_finite(name, x, *, axis_name=None, sync=False):
  """ValueError naming `name` and the first index where `x` is not finite (NaN or inf).

  Host values (numpy, Python) are checked; traced values never; a concrete JAX array only
  with `sync` (one flag is fetched from the device, the array itself only when it is bad).
  `axis_name` names the leading axis in the message ("sample", "row"): the error then names
  the leading index only.
  """
  if is_traced(x):
    return
  if isinstance(x, jax.Array):
    if not sync or x.size == 0 or not jnp.issubdtype(x.dtype, jnp.inexact) or bool(
        all_finite(x)):
      return
  values = np.asarray(x)
  if not np.issubdtype(values.dtype, np.floating) and not np.issubdtype(values.dtype,
                                                                        np.complexfloating):
    return
  index = first_non_finite(values)
  if index is None:
    return
  if axis_name is not None and index:
    bad = ~np.isfinite(values.reshape(values.shape[0], -1)).all(axis=1)
    raise ValueError(f"{name}[{index[0]}] ({axis_name} {index[0]}) is not finite "
                     f"({int(bad.sum())} of {len(bad)} {axis_name}s hold NaN or inf)")
  where = f"[{', '.join(map(str, index))}]" if index else ""
  raise ValueError(f"{name}{where} is not finite ({values[index]})")


def all_finite(x):
  """Scalar bool: every entry of `x` is finite (jnp: usable under jit)."""
  return jnp.all(jnp.isfinite(x))


def nan_unless(ok, x):
  """`x` where the scalar bool `ok` holds, NaN (of x's dtype, same shape) where it does not.

  The traced half of the convention: a value that cannot raise makes the answer NaN. Where
  `ok` holds, `x` and the gradient through it are unchanged, bit for bit.
  """
  x = jnp.asarray(x)
  return jnp.where(ok, x, jnp.asarray(jnp.nan, x.dtype))


def check_shape(name, x, shape, what=None):
  """ValueError naming `name` unless `np.shape(x)` matches `shape` (None: any size)."""
  got = tuple(np.shape(x))
  if len(got) != len(shape) or any(s is not None and g != s for g, s in zip(got, shape,
                                                                             strict=True)):
    want = "[" + ", ".join("?" if s is None else str(s) for s in shape) + "]"
    raise ValueError(f"{name} must have shape {want}{' (' + what + ')' if what else ''}, "
                     f"got {list(got)}")


def check_float_dtype(name, x, what="floats"):
  """ValueError naming `name` unless `x` holds floats: an integer or bool array (a uint8
  colour, say) is refused, since its values are on another scale (0..255) than the floats
  the function takes. Python numbers pass (they are weakly typed: `(1, 1, 1)` is the float
  colour white). Dtypes are static, so this also holds under `jit`."""
  for leaf in jax.tree.leaves(x):
    dtype = np.dtype(leaf.dtype if hasattr(leaf, "dtype") else np.asarray(leaf).dtype)
    weak = isinstance(leaf, (int, float)) and not isinstance(leaf, bool) or (
        isinstance(leaf, jax.Array) and jax.typeof(leaf).weak_type)
    if dtype == np.bool_ or (np.issubdtype(dtype, np.integer) and not weak):
      raise ValueError(f"{name} must hold {what}, got dtype {dtype}")


def concrete_bool(fn, *args):
  """`bool(fn(*args))` for concrete `args`, evaluated at once even while a caller is being
  traced (a function closed over a concrete model inside `jit` or `grad`): one flag is
  fetched from the device."""
  with jax.ensure_compile_time_eval():
    return bool(fn(*args))


def check_real_dtype(name, x):
  """ValueError naming `name` unless `x` holds real numbers (ints, floats or bools)."""
  dtype = np.asarray(x).dtype if not hasattr(x, "dtype") else np.dtype(x.dtype)
  if not (np.issubdtype(dtype, np.number) or dtype == np.bool_) or np.issubdtype(
      dtype, np.complexfloating):
    raise ValueError(f"{name} must hold real numbers, got dtype {dtype}")


def _is_real(value):
  if isinstance(value, bool) or isinstance(value, np.bool_):
    return False
  if isinstance(value, Real):
    return True
  return np.ndim(value) == 0 and np.issubdtype(np.asarray(value).dtype, np.number) and not \
      np.issubdtype(np.asarray(value).dtype, np.complexfloating)


def _interval(minimum, maximum, above, below):
  """" in [a, b)", " > a", ... : the allowed values in words."""
  low = (f"[{minimum}", minimum) if minimum is not None else (f"({above}", above) \
      if above is not None else None
  high = (f"{maximum}]", maximum) if maximum is not None else (f"{below})", below) \
      if below is not None else None
  if low and high:
    return f" in {low[0]}, {high[0]}"
  if low:
    return f" {'>=' if minimum is not None else '>'} {low[1]}"
  if high:
    return f" {'<=' if maximum is not None else '<'} {high[1]}"
  return ""


def _describe(value):
  shape = getattr(value, "shape", None)
  if shape is not None:
    return f"{type(value).__name__} of shape {list(shape)} and dtype {value.dtype}"
  text = repr(value)
  return text if len(text) <= 60 else text[:60] + "..."
