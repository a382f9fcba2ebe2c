"""Several processes on `jax.distributed`: two processes on localhost, two host devices each,
gloo collectives between them.

The processes are subprocesses of the test: they share nothing, so each compiles what it
runs. The configs are tiny, with one capacity bucket (one compilation of the step), and the
steps few. The single-process reference
runs in the test process on its one device.
"""

import json
import os
import socket
import subprocess
import sys
import textwrap
import time

import jax
import numpy as np
import pytest
from conftest import tiny_config, tiny_start, train_with, xla_flags_with_host_devices

from mfsample import config_blocks, distributed
from mfsample import view_uncertainty as unc
from mfsample.samplers import sample_z
from mfsample.train import checkpoint as ckpt
from mfsample.train import loop

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# The data-parallel run of these tests: 4 views per step, a densification after step 3.
# (300 points and at most 384 Gaussians: one capacity bucket, one compilation of the step.)
OVERRIDES = {"train.batch_size": 4, "train.num_steps": 6, "train.checkpoint_every": 3,
             "model.init_points": 300, "model.max_gaussians": 384, "densify.start": 2,
             "densify.every": 3, "densify.stop": 5, "eval.save_images": 1,
             "eval.uncertainty_samples": 0}

# A run split over four devices against the same run on one: integer leaves (counts
# included) equal; for every float leaf, nine components in ten within NORMWISE of the leaf's
# largest magnitude and every one within ADAM_OUTLIERS of it. Why: the four views' gradients
# and NDC gradient norms are float32 sums in another order (the devices' partial sums added
# by psum), a few roundings apart (~1e-7 relative). Adam divides the first moment by the
# root of the second, so a gradient component that is small against the roundings of the
# others is updated in a direction those roundings decide: its parameter then differs by up
# to a learning rate a step. Measured after 6 steps: the 90th percentile of every leaf below
# 1e-4 of its magnitude, the largest component up to 3e-2 (which components, and by how
# much, changes from run to run: the order of the devices' partial sums is not fixed). A
# view missing from a step, or counted twice, changes Adam's first moment (linear in the
# gradients) by about a quarter of its magnitude in most of its components.
NORMWISE = 1e-3
ADAM_OUTLIERS = 0.1


def _config(**extra):
  return tiny_config("lowrank", **{**OVERRIDES, **extra})


def _free_port():
  with socket.socket() as s:
    s.bind(("localhost", 0))
    return s.getsockname()[1]


def _environment(devices, **extra):
  """A subprocess's environment: CPU, `devices` host devices, `extra` variables."""
  env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=ROOT,
             XLA_FLAGS=xla_flags_with_host_devices(devices))
  env.update({k: str(v) for k, v in extra.items()})
  return env


def _launch(code, num_processes, devices, timeout, args=(), **env):
  """Runs `code` (with `args`) in `num_processes` processes of one distributed run, each with
  `devices` host devices; their (return code, stdout, stderr)."""
  port = _free_port()
  procs = []
  for i in range(num_processes):
    e = _environment(devices, MFSAMPLE_DISTRIBUTED=1, JAX_COORDINATOR_ADDRESS=f"localhost:{port}",
                     MFSAMPLE_NUM_PROCESSES=num_processes, MFSAMPLE_PROCESS_ID=i, **env)
    procs.append(subprocess.Popen([sys.executable, "-c", code, *args], cwd=ROOT, env=e,
                                  text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE))
  outputs = []
  try:
    for p in procs:
      out, err = p.communicate(timeout=timeout)
      outputs.append((p.returncode, out, err))
  finally:
    for p in procs:
      if p.poll() is None:
        p.kill()
  return outputs


def _result(stdout):
  line = [x for x in stdout.splitlines() if x.startswith("RESULT ")][-1]
  return json.loads(line[len("RESULT "):])


@pytest.fixture(scope="module")
def reference(tiny_dataset, tmp_path_factory):
  """The single-process run (this process's one device): straight through, and the first
  3 steps of it as checkpoints in the workdir the two processes will resume."""
  config = _config()
  root = tmp_path_factory.mktemp("distributed")
  straight = train_with(config, tiny_dataset)
  resumed = str(root / "two_processes")
  train_with(config, tiny_dataset, checkpoint_dir=os.path.join(resumed, "checkpoints"),
             checkpoint_every=config.train.checkpoint_every, stop_at=3)
  return config, straight, resumed


def _assert_states_close(a, b):
  """`a` against the reference `b`, leaf by leaf (`NORMWISE`)."""
  for i, (x, y) in enumerate(zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)):
    x, y = np.asarray(x), np.asarray(y)
    assert x.shape == y.shape and x.dtype == y.dtype, i
    if np.issubdtype(x.dtype, np.floating) and x.size:
      diff, scale = np.abs(x - y), np.max(np.abs(y))
      assert np.quantile(diff, 0.9) <= NORMWISE * scale, i
      assert np.max(diff) <= ADAM_OUTLIERS * scale, i
    else:
      np.testing.assert_array_equal(x, y, err_msg=str(i))


# What a subprocess starts with: the test's config (`OVERRIDES`, passed as its first argument).
_CONFIG = textwrap.dedent("""
    import json, sys
    sys.path.insert(0, "tests")
    from conftest import tiny_config, train_with
    from mfsample.config_blocks import data_spec, render_settings
    config = tiny_config("lowrank", **json.loads(sys.argv[1]))
""")

_FOUR_DEVICES = _CONFIG + textwrap.dedent("""
    import jax, numpy as np
    assert jax.device_count() == 4, jax.devices()
    from mfsample.data import datasets as data_lib
    from mfsample.train import loop
    dataset = data_lib.load_dataset(data_spec(config.data))
    result = train_with(config, dataset)
    assert result.setup.step_config.num_devices == 4
    np.savez(sys.argv[2], *[np.asarray(x) for x in jax.tree.leaves(result.state)])
""")


@pytest.mark.slow
def test_a_batch_of_four_views_on_four_devices_trains_as_on_one(reference, tmp_path):
  config, straight, _ = reference
  out = tmp_path / "state.npz"
  proc = subprocess.run([sys.executable, "-c", _FOUR_DEVICES, json.dumps(OVERRIDES), str(out)],
                        cwd=ROOT, env=_environment(4), capture_output=True, text=True,
                        timeout=600)
  assert proc.returncode == 0, proc.stderr[-3000:]
  with np.load(out) as f:
    leaves = [f[f"arr_{i}"] for i in range(len(f.files))]
  assert straight.setup.step_config.num_devices == 1  # this process has one device
  _assert_states_close(leaves, jax.tree.leaves(straight.state))


_TWO_PROCESSES = _CONFIG + textwrap.dedent("""
    import hashlib
    from mfsample import distributed
    assert distributed.initialize_from_environment()
    import jax, numpy as np
    assert jax.process_count() == 2 and jax.device_count() == 4, jax.devices()
    from mfsample import view_uncertainty as unc
    from mfsample.data import datasets as data_lib
    from mfsample.samplers import sample_z
    from mfsample.train.experiment import JOB
    state = JOB.run(config, sys.argv[2])  # resumes the workdir's checkpoint at step 3
    # Candidate scoring: U of every camera of the dataset, split over the 4 devices.
    dataset = data_lib.load_dataset(data_spec(config.data))
    cameras = jax.tree.map(lambda a, b: np.concatenate([a, b]), dataset.train.cameras,
                           dataset.test.cameras)
    z = sample_z(state.model, 2)
    scores, _ = unc.score_cameras(state.model, cameras, z,
                                  settings=render_settings(config.render))
    digest = hashlib.sha256(b"".join(np.asarray(x).tobytes()
                                     for x in jax.tree.leaves(state))).hexdigest()
    print("RESULT " + json.dumps({"process": jax.process_index(), "digest": digest,
                                  "scores": np.asarray(scores.values).tolist()}))
""")


@pytest.mark.slow
def test_two_processes_resume_train_and_score_as_one(reference, tiny_dataset):
  """Two processes of two host devices each resume the single-process run's checkpoint
  (step 3) and finish it (steps 4-6 split over the 4 devices of both), evaluate it (only
  process 0 writes the workdir) and score candidate cameras: the model, the metrics and
  the scores equal the single-process run's to float rounding, and both processes hold the
  same model and scores bit for bit."""
  config, straight, workdir = reference
  outputs = _launch(_TWO_PROCESSES, 2, 2, timeout=600, args=(json.dumps(OVERRIDES), workdir))
  for rc, _, err in outputs:
    assert rc == 0, err[-3000:]
  first, second = (_result(out) for _, out, _ in outputs)
  assert (first["process"], second["process"]) == (0, 1)
  assert first["digest"] == second["digest"]  # one replicated model
  assert first["scores"] == second["scores"]

  # The model: the final checkpoint (written by process 0) against the straight run.
  plan, model = tiny_start(config, tiny_dataset)
  setup = loop.make_setup(plan.settings, model, seed=int(config.seed), extent=plan.extent,
                          num_views=len(tiny_dataset.train))
  restored = loop.restore_latest(os.path.join(workdir, "checkpoints"), setup,
                                 lambda: loop.init_state(model, setup))
  state, _, meta = restored
  assert meta["step"] == 6
  _assert_states_close(state, straight.state)
  with open(os.path.join(workdir, "metrics.json")) as f:
    metrics = json.load(f)
  assert metrics["steps"] == 6 and metrics["live_gaussians"] == straight.state.model.num_live

  # Scoring: the same model scored here on one device.
  dataset = tiny_dataset
  cameras = jax.tree.map(lambda a, b: np.concatenate([a, b]), dataset.train.cameras,
                         dataset.test.cameras)
  z = sample_z(state.model, 2)
  here, _ = unc.score_cameras(state.model, cameras, z,
                              settings=config_blocks.render_settings(config.render),
                              num_devices=1)
  np.testing.assert_allclose(first["scores"], np.asarray(here.values), rtol=1e-5)
  # Only process 0 wrote: one set of results, no stray temporaries, the lock released.
  assert sorted(os.listdir(workdir)) == sorted(
      ["checkpoints", "config.json", "images", "inputs.json", "metrics.json",
       "point_cloud.ply", "train_log.json"])
  assert [os.path.basename(p) for p in ckpt.list_checkpoints(
      os.path.join(workdir, "checkpoints"))] == ["ckpt_00000003.npz", "ckpt_00000006.npz"]


_DIES = textwrap.dedent("""
    import os, sys, time
    from mfsample import distributed, sharding
    assert distributed.initialize_from_environment()
    import jax, jax.numpy as jnp
    f = jax.jit(lambda x: sharding.map_sharded(jnp.sum, x, num_devices=jax.device_count()))
    print("first", float(jnp.sum(f(jnp.ones((4, 3))))), flush=True)
    if jax.process_index() == 1:
      os._exit(17)  # dies without a word, as a killed process would
    time.sleep(1)
    f(jnp.ones((4, 3))).block_until_ready()
    print("SURVIVED", flush=True)
""")


@pytest.mark.slow
def test_a_process_that_dies_stops_the_others_instead_of_hanging():
  t0 = time.monotonic()
  (rc0, out0, err0), (rc1, _, _) = _launch(_DIES, 2, 2, timeout=120,
                                            MFSAMPLE_HEARTBEAT_TIMEOUT=5)
  assert rc1 == 17
  assert rc0 != 0 and "SURVIVED" not in out0 and "first 12.0" in out0
  assert time.monotonic() - t0 < 90  # well before any default timeout (100 s, 300 s)
  # gloo's connections to the dead process close (the collective fails at once); at exit the
  # coordination service names the process that stopped sending heartbeats.
  assert "Connection closed by peer" in err0 or "Task 1 heartbeat timeout" in err0, err0[-3000:]


def test_a_missing_process_stops_the_run_after_the_init_timeout():
  t0 = time.monotonic()
  env = _environment(1, MFSAMPLE_DISTRIBUTED=1, JAX_COORDINATOR_ADDRESS=f"localhost:{_free_port()}",
                     MFSAMPLE_NUM_PROCESSES=2, MFSAMPLE_PROCESS_ID=0, MFSAMPLE_INIT_TIMEOUT=3)
  code = ("from mfsample import distributed\n"
          "distributed.initialize_from_environment()\nprint('CONNECTED')")
  proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                        text=True, timeout=120)
  assert proc.returncode != 0 and "CONNECTED" not in proc.stdout
  assert "waiting at most 3 s" in proc.stderr
  assert ("DistributedError: processes [1] (MFSAMPLE_PROCESS_ID) did not reach process 0 within "
          "MFSAMPLE_INIT_TIMEOUT = 3 s") in proc.stderr
  assert time.monotonic() - t0 < 60


_CONNECT = textwrap.dedent("""
    from mfsample import distributed
    try:
      distributed.initialize_from_environment()
    except distributed.DistributedError as e:
      print("ERROR", e, flush=True)
      raise SystemExit(2)
    print("CONNECTED", flush=True)
""")


@pytest.mark.slow
def test_two_processes_with_one_id_stop_at_once_naming_the_variable():
  """Three processes for a run of three, two of them with MFSAMPLE_PROCESS_ID=1: every one
  stops within seconds with one line naming the variable (JAX's service would abort them all
  with a C++ stack trace after its timeout)."""
  port = _free_port()
  t0 = time.monotonic()
  procs = [subprocess.Popen([sys.executable, "-c", _CONNECT], cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env=_environment(1, MFSAMPLE_DISTRIBUTED=1,
                                             JAX_COORDINATOR_ADDRESS=f"localhost:{port}",
                                             MFSAMPLE_NUM_PROCESSES=3, MFSAMPLE_PROCESS_ID=i))
           for i in (0, 1, 1)]
  try:
    outputs = [p.communicate(timeout=120) for p in procs]
  finally:
    for p in procs:
      if p.poll() is None:
        p.kill()
  assert time.monotonic() - t0 < 60  # the default timeouts are 300 s and 100 s
  for p, (out, err) in zip(procs, outputs, strict=True):
    assert p.returncode == 2, err[-2000:]
    (line,) = [x for x in out.splitlines() if x.startswith("ERROR")]
    assert "two processes have MFSAMPLE_PROCESS_ID=1" in line
    assert "Check failure" not in err and "ALREADY_EXISTS" not in err


def test_the_switch_alone_names_every_variable_to_set():
  """MFSAMPLE_DISTRIBUTED=1 with no other variable and no cluster to detect them from."""
  env = _environment(1, MFSAMPLE_DISTRIBUTED=1)
  for name in ("JAX_COORDINATOR_ADDRESS", "MFSAMPLE_NUM_PROCESSES", "MFSAMPLE_PROCESS_ID",
               "SLURM_JOB_ID", "OMPI_MCA_orte_hnp_uri", "TPU_WORKER_HOSTNAMES"):
    env.pop(name, None)
  proc = subprocess.run([sys.executable, "-c", _CONNECT], cwd=ROOT, env=env,
                        capture_output=True, text=True, timeout=120)
  assert proc.returncode == 2, proc.stderr[-2000:]
  assert ("ERROR JAX_COORDINATOR_ADDRESS, MFSAMPLE_NUM_PROCESSES, MFSAMPLE_PROCESS_ID unset, "
          "and no cluster JAX detects") in proc.stdout
  assert ("set JAX_COORDINATOR_ADDRESS=host:port (process 0's), MFSAMPLE_NUM_PROCESSES=n and "
          "MFSAMPLE_PROCESS_ID=i (0 .. n - 1) for every process") in proc.stdout


@pytest.mark.parametrize("address", ["localhost", "localhost:", ":12355", "localhost:abc",
                                     "localhost:0", "localhost:70000", "12355"])
def test_a_coordinator_address_without_a_port_is_named(address):
  environ = {"MFSAMPLE_DISTRIBUTED": "1", "JAX_COORDINATOR_ADDRESS": address,
             "MFSAMPLE_NUM_PROCESSES": "2", "MFSAMPLE_PROCESS_ID": "0"}
  with pytest.raises(distributed.DistributedError,
                     match=rf"^JAX_COORDINATOR_ADDRESS='{address}' must be host:port: process "
                           "0's host name or IP address and a free port, e.g. localhost:12355$"):
    distributed.initialize_from_environment(environ)
  with pytest.raises(distributed.DistributedError, match=rf"^coordinator_address='{address}'"):
    distributed.initialize(address, 2, 0)


def test_coordinator_addresses_are_split():
  assert distributed.parse_address("localhost:12355") == ("localhost", 12355)
  assert distributed.parse_address("10.0.0.1:1234") == ("10.0.0.1", 1234)
  assert distributed.parse_address("[::1]:1234") == ("::1", 1234)


@pytest.mark.parametrize("variable, value", [
    ("MFSAMPLE_DISTRIBUTED", "yes"), ("MFSAMPLE_NUM_PROCESSES", "two"),
    ("MFSAMPLE_PROCESS_ID", "-1"), ("MFSAMPLE_INIT_TIMEOUT", "0")])
def test_malformed_variables_are_named(variable, value):
  environ = {"MFSAMPLE_DISTRIBUTED": "1", "MFSAMPLE_NUM_PROCESSES": "2",
             "MFSAMPLE_PROCESS_ID": "0", variable: value}
  with pytest.raises(distributed.DistributedError, match=variable):
    distributed.initialize_from_environment(environ)


def test_a_process_id_out_of_range_is_refused():
  environ = {"MFSAMPLE_DISTRIBUTED": "1", "MFSAMPLE_NUM_PROCESSES": "2",
             "MFSAMPLE_PROCESS_ID": "2"}
  with pytest.raises(distributed.DistributedError, match="^MFSAMPLE_PROCESS_ID=2: process id 2 "
                                                       "is not in 0 .. 1 "
                                                       r"\(MFSAMPLE_NUM_PROCESSES=2\)$"):
    distributed.initialize_from_environment(environ)


def test_without_the_switch_nothing_is_initialised():
  assert not distributed.initialize_from_environment({"MFSAMPLE_NUM_PROCESSES": "2"})
  assert not distributed.initialize_from_environment({"MFSAMPLE_DISTRIBUTED": "0"})


def test_the_entry_point_names_a_malformed_variable(tmp_path):
  env = _environment(1, MFSAMPLE_DISTRIBUTED="2")
  proc = subprocess.run([sys.executable, "experiments/train.py", "--config=configs/train.py:tiny",
                         f"--workdir={tmp_path / 'w'}"], cwd=ROOT, env=env, capture_output=True,
                        text=True, timeout=120)
  assert proc.returncode == 2, proc.stderr[-2000:]
  assert "MFSAMPLE_DISTRIBUTED='2' must be 1" in proc.stderr
  assert not (tmp_path / "w").exists()
