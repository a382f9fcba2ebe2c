"""Random streams of registered strategies: keys that do not depend on the registry's order.

A strategy's random numbers (a random candidate, FisherRF's probes, a random start) come
from `fold_in(PRNGKey(seed), stream)` and then the round. The stream is part of the
strategy's definition in its registry, not its position there: adding, removing or
reordering strategies changes no other strategy's numbers. A new strategy leaves its stream
to `name_stream`, a number derived from its name (CRC-32: the same in every process and
release); the built-in strategies keep the numbers their published results were made with.
"""

import zlib

import jax


def name_stream(name):
  """A stream number derived from a strategy's name (31 bits of its CRC-32)."""
  return zlib.crc32(str(name).encode("utf-8")) & 0x7FFFFFFF


def check_streams(registry, what):
  """Refuses a registry ({name: spec with `.stream`}) in which two names share a stream."""
  seen = {}
  for name, spec in registry.items():
    if spec.stream in seen:
      raise ValueError(f"{what} {name!r} and {seen[spec.stream]!r} share the random stream "
                       f"{spec.stream}")
    seen[spec.stream] = name


def stream_key(seed, stream, *path):
  """The PRNG key fold_in(...fold_in(PRNGKey(seed), stream)..., path)."""
  key = jax.random.fold_in(jax.random.PRNGKey(int(seed)), int(stream))
  for p in path:
    key = jax.random.fold_in(key, int(p))
  return key
