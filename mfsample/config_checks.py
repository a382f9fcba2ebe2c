"""Config validation on entry: every error names the field, its value and what is allowed.

Most rules live with the typed settings a config block is translated into (`translated`
re-raises a settings object's error naming the config field); the checks below serve the
fields that only a job reads.

Experiments call these before they write anything, so a bad command line fails at once
with a message such as

  config.train.checkpoint_every = 0: must be an integer >= 1

instead of a ZeroDivisionError an hour later. `field` is a dotted path into the config
(`"train.checkpoint_every"`); `prefix` names the config in messages (`"config.round_train"`).
"""

import contextlib
import re
from numbers import Integral

from mfsample import settings_checks as sc
from mfsample.settings_checks import SettingsError


class ConfigError(ValueError):
  """A config field outside its valid range, or of the wrong type."""


def get_field(config, field):
  """The value at a dotted path of a ConfigDict (or nested dicts)."""
  node = config
  for part in field.split("."):
    try:
      node = node[part]
    except (KeyError, AttributeError):
      raise ConfigError(f"config.{field}: the config has no such field") from None
  return node


def _name(prefix, field):
  return f"{prefix}.{field}"


def _by_rule(check, config, field, prefix, *args, **kwargs):
  """The config field checked by a `settings_checks` rule (the rules are stated once there),
  its error naming the config field."""
  value = get_field(config, field)
  try:
    return check(field, value, *args, **kwargs)
  except sc.SettingsError as e:
    raise ConfigError(f"{_name(prefix, field)} = {value!r}: must be {e.rule}") from None


def check_int(config, field, *, minimum=None, maximum=None, optional=False, prefix="config"):
  """An integer in [minimum, maximum] (None when `optional`). Returns it."""
  return _by_rule(sc.check_int, config, field, prefix, minimum=minimum, maximum=maximum,
                  optional=optional)


def check_float(config, field, *, minimum=None, maximum=None, above=None, below=None,
                optional=False, prefix="config"):
  """A finite number with minimum <= value <= maximum, above < value < below. Returns it."""
  return _by_rule(sc.check_float, config, field, prefix, minimum=minimum, maximum=maximum,
                  above=above, below=below, optional=optional)


def check_bool(config, field, *, prefix="config"):
  """True or False (not 0 / 1, not a string). Returns it."""
  value = get_field(config, field)
  if not isinstance(value, bool):
    raise ConfigError(f"{_name(prefix, field)} = {value!r}: must be True or False")
  return value


def check_str(config, field, *, non_empty=False, optional=False, prefix="config"):
  """A string (non-empty when `non_empty`; None when `optional`). Returns it."""
  value = get_field(config, field)
  if value is None and optional:
    return None
  if not isinstance(value, str) or (non_empty and not value):
    raise ConfigError(f"{_name(prefix, field)} = {value!r}: must be a "
                      + ("non-empty " if non_empty else "") + "string"
                      + (" or None" if optional else ""))
  return value


def check_floats(config, field, length, *, minimum=None, maximum=None, increasing=False,
                 prefix="config"):
  """A list or tuple of `length` finite numbers in [minimum, maximum], strictly increasing
  when `increasing` (a (low, high) range). Returns it as a tuple of floats."""
  return _by_rule(sc.check_floats, config, field, prefix, length, minimum=minimum,
                  maximum=maximum, increasing=increasing)


def check_order(config, low_field, high_field, *, strict=False, prefix="config"):
  """config.low_field <= config.high_field (< when `strict`), both already checked."""
  low, high = get_field(config, low_field), get_field(config, high_field)
  if (low is not None and high is not None) and (high < low or (strict and high == low)):
    relation = "<" if strict else "<="
    raise ConfigError(f"{_name(prefix, low_field)} = {low!r} must be {relation} "
                      f"{_name(prefix, high_field)} = {high!r}")


def check_choice(config, field, choices, *, prefix="config"):
  """One of `choices`. Returns it."""
  value = get_field(config, field)
  if value not in choices:
    raise ConfigError(f"{_name(prefix, field)} = {value!r}: must be one of "
                      f"{', '.join(repr(c) for c in choices)}")
  return value


def check_sequence(config, field, *, item_choices=None, item_minimum=None, min_length=1,
                   distinct=False, prefix="config"):
  """A list or tuple of at least `min_length` items, each in `item_choices` / an integer
  >= `item_minimum` when given, all different when `distinct`. Returns it as a tuple."""
  value = get_field(config, field)
  name = _name(prefix, field)
  if isinstance(value, (str, bytes)) or not hasattr(value, "__len__"):
    raise ConfigError(f"{name} = {value!r}: must be a list or tuple")
  items = tuple(value)
  if len(items) < min_length:
    raise ConfigError(f"{name} = {value!r}: must hold at least {min_length} item(s)")
  for item in items:
    if item_choices is not None and item not in item_choices:
      raise ConfigError(f"{name}: {item!r} is not one of "
                        f"{', '.join(repr(c) for c in item_choices)}")
    if item_minimum is not None and (isinstance(item, bool) or not isinstance(item, Integral)
                                     or item < item_minimum):
      raise ConfigError(f"{name}: {item!r} is not an integer >= {item_minimum}")
  if distinct:
    repeated = sorted({repr(i) for i in items if items.count(i) > 1})
    if repeated:
      raise ConfigError(f"{name} = {value!r}: repeats {', '.join(repeated)}; each must "
                        "appear once")
  return items


def with_variants(config, variant, variants, where):
  """`config` changed by the comma-separated `variant` names, in order (`variants`: {name:
  function(config)}); `where` names the config file in the error for an unknown name."""
  for name in filter(None, (v.strip() for v in str(variant).split(","))):
    if name not in variants:
      raise ValueError(f"unknown variant {name!r} of {where}; known: {', '.join(variants)}")
    variants[name](config)
  return config


_WHERE = re.compile(r"^(\w+)\.(\w+)(?:\[(.+)\])?$")


@contextlib.contextmanager
def translated(fields, prefix="config"):
  """Re-raises a `SettingsError` of the block (the settings built from a config block) as a
  `ConfigError` naming the config field.

  Args:
    fields: {"Class.field" or "Class": dotted config path}: a class alone maps its fields
      by name ("LossSettings": "loss" names LossSettings.ssim_weight "loss.ssim_weight"); a
      mapping field's key is appended ("OptimSettings.b_hat_lr": "sampler.lr" names
      b_hat_lr['means'] "sampler.lr.means").
    prefix: the config's name in messages ("config", "config.round_train").
  """
  try:
    yield
  except SettingsError as e:
    raise ConfigError(f"{prefix}.{config_field(e.where, fields)} = {e.value!r}: must be "
                      f"{e.rule}") from None


def config_field(where, fields):
  """The dotted config path of a settings field `where` ("Class.field[key]")."""
  m = _WHERE.match(where)
  if m is None:
    return where
  cls, field, key = m.groups()
  key = key.strip("'\"") if key else None
  if f"{cls}.{field}" in fields:
    path = fields[f"{cls}.{field}"]
  elif cls in fields:
    path = f"{fields[cls]}.{field}" if fields[cls] else field
  else:
    return where
  if key:
    path = f"{path}.{key}" if path else key
  return path
