"""Hostile inputs to the capture cache of mfsample.scenes.

For each entry point, a table of bad inputs and what they give: each row is a bad input and
its expected outcome, a clear error whose message names the field or the file, or a defined
behaviour (docs/reliability.md lists the same tables).
"""

import numpy as np
import pytest
from hostile_testlib import NAN

from mfsample.scenes import cache

# ====================================================================== the capture cache


@pytest.mark.parametrize("write, message", [
    (lambda p: p.write_bytes(b""), "unreadable cache entry"),
    (lambda p: p.write_bytes(b"PK\x03\x04 truncated"), "unreadable cache entry"),
    (lambda p: np.savez(p, radiance=np.zeros((4, 4, 3))), "has no array 'alpha'"),
    (lambda p: np.savez(p, radiance=np.zeros((4, 5, 3)), alpha=np.zeros((4, 4)),
                        depth=np.zeros((4, 4))), r"radiance has shape \(4, 5, 3\)"),
    (lambda p: np.savez(p, radiance=np.full((4, 4, 3), NAN), alpha=np.zeros((4, 4)),
                        depth=np.zeros((4, 4))), "radiance has non-finite values"),
    (lambda p: np.savez(p, radiance=np.array([None]), alpha=np.zeros((4, 4)),
                        depth=np.zeros((4, 4))), "unreadable cache entry"),  # pickled
])
def test_unusable_capture_cache_entries_are_recomputed(tmp_path, write, message):
  path = tmp_path / "rgbad-entry.npz"
  write(path)
  expected = {"radiance": (4, 4, 3), "alpha": (4, 4), "depth": (4, 4)}
  with pytest.warns(UserWarning, match=rf"rgbad-entry.npz: .*{message}|{message} .*rgbad-entry"):
    assert cache.load(path, expected) is None
  cache.save(path, {k: np.zeros(s, np.float32) for k, s in expected.items()})
  assert set(cache.load(path, expected)) == set(expected)  # the recomputed entry replaces it
