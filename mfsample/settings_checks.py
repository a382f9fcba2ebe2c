"""Checks of frozen settings objects: one rule per field, stated once, named in every error.

Every typed settings object of the library (`RenderSettings`, `TrainSettings`, `DataSpec`,
...) checks its fields on construction with these helpers. An error is a `SettingsError`
that knows the field (`where`: "TrainSettings.num_steps"), the value and the rule, so the
same rule serves two audiences: a library call reads

  TrainSettings.num_steps must be an integer >= 1, got 0

and a job, whose translator builds the settings from a config block, re-raises it naming
the config field (`mfsample.config_checks.translated`):

  config.train.num_steps = 0: must be an integer >= 1
"""

import math
from numbers import Integral, Real

from mfsample.arg_checks import _interval


class SettingsError(ValueError):
  """A settings field outside its rule.

  Attributes:
    where: "Class.field" (or "Class.field[key]").
    value: the value given.
    rule: what is allowed, in words ("an integer >= 1").
  """

  def __init__(self, where, value, rule):
    self.where, self.value, self.rule = where, value, rule
    super().__init__(f"{where} must be {rule}, got {value!r}")


def check_int(where, value, *, minimum=None, maximum=None, optional=False):
  """An integer in range (None when `optional`); bools and floats are refused."""
  if value is None and optional:
    return None
  ok = isinstance(value, Integral) and not isinstance(value, bool)
  ok = ok and (minimum is None or value >= minimum) and (maximum is None or value <= maximum)
  if not ok:
    raise SettingsError(where, value, f"an integer{_interval(minimum, maximum, None, None)}"
                        + (" or None" if optional else ""))
  return int(value)


def check_float(where, value, *, minimum=None, maximum=None, above=None, below=None,
                optional=False):
  """A finite real number in range (None when `optional`); bools are refused."""
  if value is None and optional:
    return None
  ok = isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)
  ok = ok and (minimum is None or value >= minimum) and (maximum is None or value <= maximum)
  ok = ok and (above is None or value > above) and (below is None or value < below)
  if not ok:
    raise SettingsError(where, value, "a finite number"
                        + _interval(minimum, maximum, above, below)
                        + (" or None" if optional else ""))
  return float(value)


def check_bool(where, value):
  """True or False (not 0 / 1, not a string)."""
  if not isinstance(value, bool):
    raise SettingsError(where, value, "True or False")
  return value


def check_str(where, value, *, non_empty=False):
  """A string (non-empty when `non_empty`)."""
  if not isinstance(value, str) or (non_empty and not value):
    raise SettingsError(where, value, ("a non-empty " if non_empty else "a ") + "string")
  return value


def check_choice(where, value, choices):
  """One of `choices`."""
  if isinstance(value, bool) or value not in choices:
    raise SettingsError(where, value, "one of " + ", ".join(repr(c) for c in choices))
  return value


def check_names(where, value, choices, *, min_length=0):
  """A tuple of distinct names from `choices` (a list is accepted and made a tuple)."""
  if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list)):
    raise SettingsError(where, value, "a tuple of names")
  items = tuple(value)
  for item in items:
    if item not in choices:
      raise SettingsError(where, value, f"a tuple of names from "
                          f"{', '.join(repr(c) for c in choices)} ({item!r} is not one)")
  repeated = sorted({repr(i) for i in items if items.count(i) > 1})
  if repeated:
    raise SettingsError(where, value, f"a tuple of distinct names ({repeated[0]} repeats)")
  if len(items) < min_length:
    raise SettingsError(where, value, f"{min_length} or more names")
  return items


def check_floats(where, value, length, *, minimum=None, maximum=None, increasing=False):
  """A tuple of `length` finite numbers in range (strictly increasing when asked)."""
  rule = (f"{length} finite numbers{_interval(minimum, maximum, None, None)}"
          + (", strictly increasing" if increasing else ""))
  if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != length:
    raise SettingsError(where, value, rule)
  items = tuple(value)
  for item in items:
    if (isinstance(item, bool) or not isinstance(item, Real) or not math.isfinite(item)
        or (minimum is not None and item < minimum) or (maximum is not None and item > maximum)):
      raise SettingsError(where, value, rule)
  if increasing and any(b <= a for a, b in zip(items[:-1], items[1:], strict=True)):
    raise SettingsError(where, value, rule)
  return tuple(float(v) for v in items)


def check_table(where, value, keys, *, minimum=None, above=None):
  """A {key: finite number} mapping (or (key, number) pairs) over `keys` -> sorted pairs.

  Every key must be one of `keys`; each number is checked like `check_float`, named
  `where[key]`. Pairs are what a frozen, hashable settings object holds.
  """
  items = value.items() if hasattr(value, "items") else value
  try:
    pairs = [(k, v) for k, v in items]
  except (TypeError, ValueError):
    raise SettingsError(where, value, "a mapping from names to numbers") from None
  seen = set()
  for k, v in pairs:
    if k not in keys:
      raise SettingsError(where, value, f"a mapping from names in "
                          f"{', '.join(repr(c) for c in keys)} to numbers (it names an unknown "
                          f"group {k!r})")
    if k in seen:
      raise SettingsError(where, value, f"a mapping with one number per name (it gives two "
                          f"for {k!r})")
    seen.add(k)
    check_float(f"{where}[{k!r}]", v, minimum=minimum, above=above)
  order = {k: i for i, k in enumerate(keys)}
  return tuple(sorted(((k, float(v)) for k, v in pairs), key=lambda kv: order[kv[0]]))


def set_field(obj, name, value):
  """Sets a field of a frozen dataclass during its `__post_init__` (normalised values)."""
  object.__setattr__(obj, name, value)
