"""Test-session setup.

The suite is dominated by XLA compilation of many small, distinct programs, not by running
them. LLVM's backend optimisation level 0 cuts that CPU time by about a third (measured on
tests/test_render.py) without changing results: floating-point semantics are set by XLA's
own flags, not by the LLVM pass pipeline. A user-provided XLA_FLAGS is respected.

The test workers and the subprocesses tests start compile many of the same programs (the
tiny scene's training step, its renders): JAX's persistent compilation cache, in a folder
of this test run only (removed at its end), lets the second compilation be a read. A
user-provided JAX_COMPILATION_CACHE_DIR is respected.
"""

import atexit
import os
import shutil
import tempfile

if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
  os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "")
                             + " --xla_backend_optimization_level=0").strip()

# One folder per test run, made by the first process that loads this file (pytest's
# controller, or the only process); the workers and the subprocesses of tests inherit it.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
  os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="mfsample-tests-xla-cache-")
  os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")
  atexit.register(shutil.rmtree, os.environ["JAX_COMPILATION_CACHE_DIR"], ignore_errors=True)


import pytest  # noqa: E402

# ------------------------------------------------------------------------- memory maps
# A test worker compiles thousands of distinct programs, and every XLA CPU executable holds
# memory maps of its own. Linux caps a process's maps (vm.max_map_count, 65530 by default);
# at the cap a compilation fails inside XLA and the compiling thread waits for it forever
# (the suite hangs near its end, with the worker idle in `backend_compile_and_load`). So
# the compiled functions are dropped once a worker holds half the cap: the next tests
# compile again, which costs seconds, not a hang.


def _map_count():
  """(maps this process holds, the system's cap), or None where /proc does not say."""
  try:
    with open("/proc/self/maps", "rb") as f:
      held = sum(1 for _ in f)
    with open("/proc/sys/vm/max_map_count") as f:
      return held, int(f.read())
  except (OSError, ValueError):
    return None


@pytest.fixture(autouse=True)
def _bounded_memory_maps():
  yield
  counts = _map_count()
  if counts is not None and counts[0] > counts[1] // 2:
    import gc

    import jax

    jax.clear_caches()
    gc.collect()


# ------------------------------------------------------------------------- training fixtures
# A tiny synthetic scene rendered once per session. Compiled functions are shared through the
# library's module-level jits (`render`, `train_step_jit`, which take their settings as
# static arguments): tests that build equal configs reuse one compilation.

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


def tiny_start(config, dataset):
  """(the `Recipe` of a training config on `dataset`, its step-0 `Model`), as the training
  job builds them: the scene's extent from the training cameras unless the config fixes it."""
  from mfsample.train.config import recipe

  extent = config.data.extent
  if extent is None:
    extent = data_lib.scene_extent(dataset.train.cameras)
  plan = recipe(config, extent=extent)
  return plan, plan.initial_model(seed=int(config.seed), bounds=dataset.bounds,
                                  points=dataset.points)


def train_with(config, dataset, **kwargs):
  """`run_training` of a training config on `dataset` (what the training job trains)."""
  from mfsample.train.loop import run_training

  plan, model = tiny_start(config, dataset)
  return run_training(model, dataset.train, plan.settings, seed=int(config.seed),
                      extent=plan.extent, **kwargs)


@pytest.fixture(scope="session")
def tiny_dataset():
  """`Dataset` of random Gaussians seen by 12 training and 4 test cameras at 32 x 32."""
  from mfsample.config_blocks import data_spec

  return data_lib.load_dataset(data_spec(train_configs.get_config("tiny").data))
