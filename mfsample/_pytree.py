"""Frozen dataclasses registered as JAX pytrees.

Array fields are pytree leaves (differentiable, vmappable); fields declared with
`static_field()` are metadata: part of the tree structure, so they must be hashable and a
change of them retraces a jitted function, exactly like a static argument.
"""

import dataclasses

import jax

_STATIC = "mfsample_static"


def static_field(**kwargs):
  """A dataclass field that is pytree metadata rather than a leaf."""
  return dataclasses.field(metadata={_STATIC: True}, **kwargs)


def pytree_dataclass(cls):
  """Decorator: a frozen dataclass whose non-static fields are pytree children."""
  cls = dataclasses.dataclass(frozen=True)(cls)
  fields = dataclasses.fields(cls)
  data = [f.name for f in fields if not f.metadata.get(_STATIC, False)]
  meta = [f.name for f in fields if f.metadata.get(_STATIC, False)]
  return jax.tree_util.register_dataclass(cls, data_fields=data, meta_fields=meta)


def replace(obj, **changes):
  """`dataclasses.replace`, re-exported so callers need not import dataclasses."""
  return dataclasses.replace(obj, **changes)
