"""Shared fixtures: a tiny synthetic scene rendered once per test session.

Compiled functions are shared through the library's module-level jits (`render_jit`,
`train_step_jit`, which take their settings as static arguments): tests that build equal
configs reuse one compilation.
"""

import pytest

from configs import train_synthetic
from mfsample.train import data as data_lib


def tiny_config(kind="lowrank", **overrides):
  """The synthetic training config with `sampler.kind = kind` and dotted `overrides`."""
  config = train_synthetic.get_config()
  config.sampler.kind = kind
  for name, value in overrides.items():
    node = config
    *parents, leaf = name.split(".")
    for p in parents:
      node = node[p]
    node[leaf] = value
  return config


@pytest.fixture(scope="session")
def tiny_dataset():
  """`Dataset` of random Gaussians seen by 12 training and 4 test cameras at 32 x 32."""
  return data_lib.load_dataset(train_synthetic.get_config().data)
