"""Reading .ply files as other tools do, for the tests of the files mfsample writes
(`tests/data/test_ply.py`, `tests/your_data/test_uncertainty_ply.py`)."""

from pathlib import Path

import numpy as np


def fixed_records(path):
  """[N, 62] float32: a .ply read as the reference SIBR viewer reads it, trusting nothing of
  the header but the vertex count: fixed records of 62 little-endian floats after it."""
  data = Path(path).read_bytes()
  head, body = data.split(b"end_header\n", 1)
  count = int(next(line.split()[2] for line in head.decode().splitlines()
                   if line.startswith("element vertex")))
  return np.frombuffer(body[:count * 62 * 4], "<f4").reshape(count, 62)
