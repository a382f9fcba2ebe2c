"""Runs over several processes (machines, or one process per GPU) on `jax.distributed`.

Every process runs the same program on the same config and data. After
`jax.distributed.initialize`, `jax.devices()` lists the devices of every process, and a
function split over them (`mfsample.sharding`) runs on all processes at once, each feeding
its own devices, with collectives between them (NCCL on GPUs, gloo on CPUs). Everything
else (the host loop, densification, evaluation) each process computes alike. One process,
process 0, writes the workdir (`is_writer`; `mfsample.jobs`).

The entry points initialise from the environment (`initialize_from_environment`):

  MFSAMPLE_DISTRIBUTED=1             required: nothing happens without it
  JAX_COORDINATOR_ADDRESS=host:port  process 0's address (JAX reads it)
  MFSAMPLE_NUM_PROCESSES=n           number of processes
  MFSAMPLE_PROCESS_ID=i              this process, 0 .. n - 1
  MFSAMPLE_INIT_TIMEOUT=300          seconds to wait for every process to connect
  MFSAMPLE_HEARTBEAT_TIMEOUT=100     seconds without a sign of life before a process is
                                     declared dead and every other one is stopped

Unset, the coordinator address, the number of processes and the process id come from
JAX's cluster detection (SLURM, Open MPI, Kubernetes, Cloud TPU: `jax.distributed`); with
none of these, the error names every variable to set. Given, the processes hold a roll call
first (`mfsample.roll_call`): two processes with one id, or with different counts, stop every
process at once with one line naming the variable.

What happens when a process fails (JAX's coordination service, measured in
tests/core/test_distributed.py): a process that is not connected within the init timeout stops
every process with an error naming the missing one; a process that dies while the others
run makes the next collective fail at once (its connections close), and the service stops
the survivors after at most the heartbeat timeout. No process waits forever.
"""

import hashlib
import os
import sys

import numpy as np

ENABLE = "MFSAMPLE_DISTRIBUTED"
ADDRESS = "JAX_COORDINATOR_ADDRESS"
NUM_PROCESSES = "MFSAMPLE_NUM_PROCESSES"
PROCESS_ID = "MFSAMPLE_PROCESS_ID"
INIT_TIMEOUT = "MFSAMPLE_INIT_TIMEOUT"
HEARTBEAT_TIMEOUT = "MFSAMPLE_HEARTBEAT_TIMEOUT"
MESSAGE_BYTES = 4096  # longest message `share_outcome` passes on (longer ones are cut)


class DistributedError(RuntimeError):
  """A multi-process run cannot go on (a bad setting, or another process failed); the
  message says which."""


def _int_env(environ, name, minimum):
  value = environ.get(name)
  if value is None or value == "":
    return None
  try:
    number = int(value)
  except ValueError:
    number = None
  if number is None or number < minimum:
    raise DistributedError(f"{name}={value!r} must be an integer >= {minimum}")
  return number


def initialize(coordinator_address=None, num_processes=None, process_id=None, *,
               init_timeout=300, heartbeat_timeout=100):
  """`jax.distributed.initialize`, with CPU collectives (gloo) for host devices.

  Call it first, before anything else runs on a device. None: JAX's cluster detection.
  With the address, the count and the id all given, the processes first hold a roll call
  (`mfsample.roll_call`): a repeated id, counts that differ or a missing process stop every
  process with one line naming the setting, not a C++ abort.

  Args:
    coordinator_address: "host:port" of process 0 (None: `JAX_COORDINATOR_ADDRESS`, or the
      cluster's).
    num_processes: processes in the run.
    process_id: this process, 0 .. num_processes - 1.
    init_timeout: seconds to wait for every process to connect.
    heartbeat_timeout: seconds of silence after which a process counts as dead.

  Raises:
    DistributedError: a malformed address, an id out of range, settings missing with no
      cluster to detect them from, or a roll call that failed; the message names the setting.
  """
  names = {"address": "coordinator_address" if coordinator_address else ADDRESS,
           "num_processes": "num_processes", "process_id": "process_id",
           "timeout": f"init_timeout = {init_timeout} s"}
  _initialize(coordinator_address, num_processes, process_id, int(init_timeout),
              int(heartbeat_timeout), names)


def _initialize(address, num_processes, process_id, init_timeout, heartbeat_timeout, names):
  """`initialize`, its messages naming the settings as `names` says (see `roll_call.call`)."""
  address = address or os.environ.get(ADDRESS) or None
  host_port = None if address is None else parse_address(address, names["address"])
  if num_processes is not None and process_id is not None and not (
      0 <= process_id < num_processes):
    raise DistributedError(f"{names['process_id']}={process_id}: process id {process_id} is not "
                           f"in 0 .. {num_processes - 1} ({names['num_processes']}="
                           f"{num_processes})")
  import jax

  # Collectives between processes on host devices (JAX's default since 0.5; set for older).
  jax.config.update("jax_cpu_collectives_implementation", "gloo")
  print(f"mfsample: process {'?' if process_id is None else process_id} of "
        f"{'?' if num_processes is None else num_processes} connecting to "
        f"{address or '(detected)'}, waiting at most {init_timeout} s for every process",
        file=sys.stderr, flush=True)
  if host_port is not None and num_processes is not None and process_id is not None and (
      num_processes > 1):
    from mfsample import roll_call

    try:
      roll_call.call(*host_port, num_processes, process_id, init_timeout, names)
    except roll_call.RollCallError as e:
      raise DistributedError(str(e)) from None
  try:
    jax.distributed.initialize(address, num_processes, process_id,
                               initialization_timeout=init_timeout,
                               **_heartbeat_arguments(heartbeat_timeout))
  except ValueError as e:  # raised before connecting: a setting nothing gave
    given = {"address": address, "num_processes": num_processes, "process_id": process_id}
    unset = [names[k] for k, v in given.items() if v is None]
    if not unset:
      raise
    raise DistributedError(
        f"{', '.join(unset)} unset, and no cluster JAX detects (SLURM, Open MPI, Kubernetes, "
        f"Cloud TPU) gave {'it' if len(unset) == 1 else 'them'} (jax: {e}); set "
        f"{names['address']}=host:port (process 0's), {names['num_processes']}=n and "
        f"{names['process_id']}=i (0 .. n - 1) for every process") from None


def parse_address(address, name=ADDRESS):
  """(host, port) of a coordinator address "host:port" ("[::1]:1234" for IPv6).

  Raises:
    DistributedError: naming `name` when it is not host:port with a port in 1 .. 65535.
  """
  host, sep, port = str(address).strip().rpartition(":")
  if not (sep and host and port.isdigit() and 1 <= int(port) <= 65535):
    raise DistributedError(f"{name}={address!r} must be host:port: process 0's host name or IP "
                           "address and a free port, e.g. localhost:12355")
  if host.startswith("[") and host.endswith("]"):
    host = host[1:-1]
  return host, int(port)


def _heartbeat_arguments(timeout):
  """`jax.distributed.initialize`'s arguments for a heartbeat timeout of `timeout` seconds:
  one number in recent JAX, an interval and a count of missed beats in older ones (0.6)."""
  import inspect

  import jax

  names = inspect.signature(jax.distributed.initialize).parameters
  if "heartbeat_timeout_seconds" in names:
    return {"heartbeat_timeout_seconds": timeout}
  interval = 1 if timeout < 10 else 10
  missing = max(1, -(-timeout // interval))
  return {"service_heartbeat_interval_seconds": interval,
          "service_max_missing_heartbeats": missing,
          "client_heartbeat_interval_seconds": interval,
          "client_max_missing_heartbeats": missing}


def initialize_from_environment(environ=None):
  """`initialize` from the variables of the module docstring; True when it ran, False when
  `MFSAMPLE_DISTRIBUTED` is unset or 0 (a single process).

  Raises:
    DistributedError: a variable is malformed, missing (with no cluster to detect it from) or
      contradicted by another process's (a repeated `MFSAMPLE_PROCESS_ID`, another
      `MFSAMPLE_NUM_PROCESSES`); the message names the variable.
  """
  environ = os.environ if environ is None else environ
  flag = environ.get(ENABLE, "").strip()
  if flag in ("", "0"):
    return False
  if flag != "1":
    raise DistributedError(f"{ENABLE}={flag!r} must be 1 (several processes) or 0")
  init_timeout = _int_env(environ, INIT_TIMEOUT, 1) or 300
  names = {"address": ADDRESS, "num_processes": NUM_PROCESSES, "process_id": PROCESS_ID,
           "timeout": f"{INIT_TIMEOUT} = {init_timeout} s"}
  _initialize(environ.get(ADDRESS) or None, _int_env(environ, NUM_PROCESSES, 1),
              _int_env(environ, PROCESS_ID, 0), init_timeout,
              _int_env(environ, HEARTBEAT_TIMEOUT, 1) or 100, names)
  return True


def process_count():
  import jax

  return jax.process_count()


def is_writer():
  """Whether this process writes results (process 0; always, in a single-process run)."""
  import jax

  return jax.process_index() == 0


def _gather(array):
  from jax.experimental import multihost_utils

  return np.asarray(multihost_utils.process_allgather(array))


def check_same_everywhere(text, what):
  """Refuses to go on unless every process passes the same `text` (a config as JSON).

  Raises:
    DistributedError: in every process, naming the processes that differ from process 0.
  """
  if process_count() == 1:
    return
  digest = np.frombuffer(hashlib.sha256(text.encode("utf-8")).digest(), np.uint8)
  digests = _gather(digest)
  differ = [i for i in range(len(digests)) if not np.array_equal(digests[i], digests[0])]
  if differ:
    raise DistributedError(f"{what} of process(es) {differ} differs from process 0's: every "
                           "process must run the same command")


def share_outcome(error):
  """Passes process 0's outcome of a step only it takes (`error`: None, or its exception)
  to every process; raises it in every other process as a `DistributedError`.

  Every process calls it at the same point; process 0 re-raises its own error itself.
  """
  if process_count() == 1:
    return
  from jax.experimental import multihost_utils

  message = b"" if error is None else f"{type(error).__name__}: {error}".encode()
  buffer = np.zeros(MESSAGE_BYTES + 1, np.uint8)
  buffer[0] = error is not None
  buffer[1:1 + min(len(message), MESSAGE_BYTES)] = np.frombuffer(
      message[:MESSAGE_BYTES], np.uint8)
  received = np.asarray(multihost_utils.broadcast_one_to_all(buffer))
  if received[0] and not is_writer():
    text = bytes(received[1:]).rstrip(b"\0").decode("utf-8", "replace")
    raise DistributedError(f"process 0 stopped: {text}")
