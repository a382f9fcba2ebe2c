"""Test-session setup.

The suite is dominated by XLA compilation of many small, distinct programs, not by running
them. LLVM's backend optimisation level 0 cuts that CPU time by about a third (measured on
tests/test_render.py) without changing results: floating-point semantics are set by XLA's
own flags, not by the LLVM pass pipeline. A user-provided XLA_FLAGS is respected.
"""

import os

if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
  os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                             + " --xla_backend_optimization_level=0").strip()


# ------------------------------------------------------------------------- training fixtures
# A tiny synthetic scene rendered once per session. Compiled functions are shared through the
# library's module-level jits (`render`, `train_step_jit`, which take their settings as
# static arguments): tests that build equal configs reuse one compilation.

import pytest  # noqa: E402

from configs import train as train_configs  # noqa: E402
from mfsample.data import datasets as data_lib  # noqa: E402


def float64():
  """A with-block that computes in float64 (finite-difference checks).

  `jax.enable_x64` in recent JAX; its predecessor `jax.experimental.enable_x64` in the older
  versions pyproject.toml admits.
  """
  import jax

  if hasattr(jax, "enable_x64"):
    return jax.enable_x64(True)
  from jax.experimental import enable_x64
  return enable_x64()


def tiny_config(kind="lowrank", **overrides):
  """The tiny training config with `sampler.kind = kind` and dotted `overrides`."""
  config = train_configs.get_config("tiny")
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
  return data_lib.load_dataset(train_configs.get_config("tiny").data)
