"""Strategies' random streams: fixed with each strategy, whatever the registry's order."""

import jax
import numpy as np
import pytest

from mfsample import streams
from mfsample.lighting import strategies as light_strategies
from mfsample.planning import strategies as camera_strategies


def test_name_streams_are_stable_31_bit_numbers():
  # CRC-32 of the name: the same number in every process (not Python's salted hash).
  assert streams.name_stream("ours_sel") == streams.name_stream("ours_sel")
  assert streams.name_stream("a") != streams.name_stream("b")
  assert 0 <= streams.name_stream("a new strategy") < 2**31
  assert streams.name_stream("a") == 0xE8B7BE43 & 0x7FFFFFFF  # zlib.crc32(b"a")


def test_two_strategies_may_not_share_a_stream():
  class Spec:
    def __init__(self, stream):
      self.stream = stream

  with pytest.raises(ValueError, match="'b' and 'a' share the random stream 3"):
    streams.check_streams({"a": Spec(3), "b": Spec(3)}, "strategies")


@pytest.mark.parametrize("module", [camera_strategies, light_strategies])
def test_adding_or_reordering_strategies_changes_no_key(module, monkeypatch):
  before = {name: np.asarray(jax.random.key_data(module.strategy_key(7, name, 2)))
            for name in module.NAMES}
  spec = next(iter(module.STRATEGIES.values()))
  grown = {"new": spec._replace(stream=streams.name_stream("new"))}
  grown.update(reversed(list(module.STRATEGIES.items())))
  monkeypatch.setattr(module, "STRATEGIES", grown)
  for name, key in before.items():
    np.testing.assert_array_equal(
        np.asarray(jax.random.key_data(module.strategy_key(7, name, 2))), key)


def test_the_built_in_strategies_keep_the_streams_of_their_published_results():
  # The camera planning and lighting results in docs/ were made with these keys:
  # fold_in(fold_in(PRNGKey(seed), stream), round).
  assert [s.stream for s in camera_strategies.STRATEGIES.values()] == list(range(9))
  assert [s.stream for s in light_strategies.STRATEGIES.values()] == list(range(5))
  key = camera_strategies.strategy_key(3, "fisher", 4)
  manual = jax.random.fold_in(jax.random.fold_in(jax.random.PRNGKey(3), 3), 4)
  np.testing.assert_array_equal(jax.random.key_data(key), jax.random.key_data(manual))
