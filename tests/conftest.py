"""Test-session setup.

Most tests compile many small, distinct XLA programs and run each once or twice (the jobs
and training loops of the slow tests run theirs many times). Three XLA CPU settings cut their
compile and run time without changing what is computed:

* LLVM's backend optimisation level 0 (about a third of the compile time of
  tests/renderer/test_render.py): floating-point semantics are set by XLA's own flags,
  not by the LLVM pass pipeline.
* XLA's classic loop-fusion code generator instead of its newer fusion emitters
  (`--xla_cpu_use_fusion_emitters=false`): the compile time of test_render.py falls from
  78 s to 24 s (one process, two CPU cores). Results agree to float rounding (a few ulp
  where two differently structured programs are compared). It is used where this JAX's
  XLA knows the flag (a subprocess asks it once per run; an unknown flag would abort).
* One LLVM module per program (`--xla_cpu_parallel_codegen_split_count=1`) instead of
  parts generated on parallel threads: with two workers on two cores no core is idle for
  those threads, and the level-0 programs run faster as one module: in the suite (`-n 2`,
  one run each) the API page's program (tests/core/test_api.py, a process of its own)
  took 42 s with it against 57 s without. Results agree to float rounding (a few ulp).

A flag already in XLA_FLAGS is respected.

The test workers and the subprocesses tests start compile many of the same programs (the
tiny scene's training step, its renders, the element-wise programs of eager code): JAX's
persistent compilation cache, in a folder of this test run only (removed at its end), lets
every compilation after the first be a read, however short it was. A user-provided
JAX_COMPILATION_CACHE_DIR is respected.
"""

import atexit
import os
import shutil
import subprocess
import sys
import tempfile

_FAST_COMPILE_FLAGS = ("--xla_backend_optimization_level=0",
                       "--xla_cpu_use_fusion_emitters=false",
                       "--xla_cpu_parallel_codegen_split_count=1")


def _xla_knows(flag):
  """Whether this JAX's XLA accepts `flag` (an unknown one aborts the process at start)."""
  probe = subprocess.run([sys.executable, "-c", "import jax; jax.devices('cpu')"],
                         env={**os.environ, "XLA_FLAGS": flag}, capture_output=True,
                         timeout=120, check=False)
  return probe.returncode == 0


# The first process that loads this file (pytest's controller, or the only process) sets
# the flags; the workers and the subprocesses of tests inherit them.
if "MFSAMPLE_TEST_XLA_FLAGS_SET" not in os.environ:
  os.environ["MFSAMPLE_TEST_XLA_FLAGS_SET"] = "1"
  for _flag in _FAST_COMPILE_FLAGS:
    if _flag.split("=")[0] not in os.environ.get("XLA_FLAGS", "") and _xla_knows(_flag):
      os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + _flag).strip()


def xla_flags_with_host_devices(count):
  """XLA_FLAGS for a subprocess with `count` host CPU devices: this run's flags and the count."""
  return f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={count}".strip()


# One folder per test run, made by the first process that loads this file; the workers and
# the subprocesses of tests inherit it.
if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
  os.environ["JAX_COMPILATION_CACHE_DIR"] = tempfile.mkdtemp(prefix="mfsample-tests-xla-cache-")
  os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
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

    import chex
    import jax

    jax.clear_caches()
    # A jitted function traces again after the clear: tests that count traces
    # (chex.assert_max_traces) start counting afresh.
    chex.clear_trace_counter()
    gc.collect()


# ------------------------------------------------------------------------- compilation report
# The suite's time is XLA compilation: the end of every run prints how many programs the test
# processes traced and compiled (and how many compilations the persistent cache answered),
# summed over the xdist workers, beside pytest's 15 slowest tests (`--durations=15`), and the
# test files that take the most time with their share of compiling (where to look first when
# the suite grows slow). Subprocesses that tests start (the jobs' command lines) are not
# counted.

_TRACE_EVENT = "/jax/core/compile/jaxpr_trace_duration"
_COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"  # compiled or read from cache
_CACHE_HIT_EVENT = "/jax/compilation_cache/cache_hits"
_compile_counts = {"traces": 0, "compile_requests": 0, "cache_hits": 0, "compile_seconds": 0.0}
_compile_seconds_by_file = {}  # test file -> seconds its tests (and fixtures) spent compiling
_current_file = [None]
_seconds_by_file = {}  # test file -> seconds of its tests (setup, call and teardown)


def _on_duration(event, duration_secs, **_):
  if event == _TRACE_EVENT:
    _compile_counts["traces"] += 1
  elif event == _COMPILE_EVENT:
    _compile_counts["compile_requests"] += 1
    _compile_counts["compile_seconds"] += duration_secs
    if _current_file[0] is not None:
      _compile_seconds_by_file[_current_file[0]] = (
          _compile_seconds_by_file.get(_current_file[0], 0.0) + duration_secs)


def _on_event(event, **_):
  if event == _CACHE_HIT_EVENT:
    _compile_counts["cache_hits"] += 1


def pytest_configure(config):
  from jax import monitoring

  monitoring.register_event_duration_secs_listener(_on_duration)
  monitoring.register_event_listener(_on_event)
  controller = not hasattr(config, "workerinput")
  config._mfsample_compile_counts = [] if controller else None
  config._mfsample_compile_by_file = [] if controller else None


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item, nextitem):
  _current_file[0] = item.location[0]
  try:
    return (yield)
  finally:
    _current_file[0] = None


def pytest_runtest_logreport(report):
  # On the controller this sees every worker's reports: the time of each file's tests.
  name = report.location[0]
  _seconds_by_file[name] = _seconds_by_file.get(name, 0.0) + report.duration


def pytest_sessionfinish(session):
  if hasattr(session.config, "workeroutput"):  # an xdist worker: hand the counts over
    session.config.workeroutput["mfsample_compile_counts"] = dict(_compile_counts)
    session.config.workeroutput["mfsample_compile_by_file"] = dict(_compile_seconds_by_file)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
  output = getattr(node, "workeroutput", {})
  if output.get("mfsample_compile_counts") is not None:
    node.config._mfsample_compile_counts.append(output["mfsample_compile_counts"])
    node.config._mfsample_compile_by_file.append(output.get("mfsample_compile_by_file", {}))


def pytest_terminal_summary(terminalreporter, config):
  runs = config._mfsample_compile_counts or [dict(_compile_counts)]
  total = {k: sum(r[k] for r in runs) for k in _compile_counts}
  compiled = total["compile_requests"] - total["cache_hits"]
  terminalreporter.write_sep("=", "XLA compilations")
  terminalreporter.write_line(
      f"{total['traces']} traces, {compiled} programs compiled "
      f"({total['cache_hits']} more read from the persistent cache), "
      f"{total['compile_seconds']:.0f} s compiling, in {len(runs)} test process(es)")
  compiling = {}
  for by_file in config._mfsample_compile_by_file or [_compile_seconds_by_file]:
    for name, secs in by_file.items():
      compiling[name] = compiling.get(name, 0.0) + secs
  seconds = _seconds_by_file
  if seconds:
    slowest = sorted(seconds, key=seconds.get, reverse=True)[:10]
    terminalreporter.write_line("slowest test files (seconds of tests, of which compiling):")
    for name in slowest:
      terminalreporter.write_line(
          f"  {seconds[name]:7.1f} {compiling.get(name, 0.0):7.1f}  {name}")


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


# ------------------------------------------------------------------------- file order
# With `-n 2 --dist loadfile` each worker takes whole files, in the order they are collected
# (`--no-loadscope-reorder`): the files that take longest go first, so that neither worker is
# left running one of them alone at the end. They are in the order of the end-of-run report's
# slowest files; a file not named keeps its place after them.
LONGEST_FILES = (
    "tests/docs/test_readme.py",
    "tests/planning/test_planning.py",
    "tests/your_data/test_next_views.py",
    "tests/renderer/test_render.py",
    "tests/lighting/test_lighting.py",
    "tests/core/test_distributed.py",
    "tests/core/test_api.py",
    "tests/train/test_train.py",
    "tests/quality/test_quality.py",
    "tests/benchmarks/test_benchmarks.py",
)


def pytest_collection_modifyitems(items):
  rank = {name: i for i, name in enumerate(LONGEST_FILES)}
  items.sort(key=lambda item: rank.get(item.location[0], len(rank)))  # stable
