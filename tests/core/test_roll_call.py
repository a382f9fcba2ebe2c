"""The roll call before `jax.distributed` (mfsample.roll_call): processes in threads of this
test, on a free localhost port; no JAX."""

import socket
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import pytest

from mfsample import roll_call

NAMES = {"address": "JAX_COORDINATOR_ADDRESS", "num_processes": "MFSAMPLE_NUM_PROCESSES",
         "process_id": "MFSAMPLE_PROCESS_ID", "timeout": "MFSAMPLE_INIT_TIMEOUT = 5 s"}


def _free_port():
  with socket.socket() as s:
    s.bind(("localhost", 0))
    return s.getsockname()[1]


def _roll_call(calls, timeout=5.0, port=None):
  """Runs `calls` [(num_processes, process_id)] at once (process 0's first, the others a little
  later, as processes start); each one's exception, or None."""
  port = port or _free_port()

  def one(args):
    num, pid = args
    if pid != 0:
      time.sleep(0.1)
    try:
      roll_call.call("localhost", port, num, pid, timeout, NAMES)
    except roll_call.RollCallError as e:
      return e
    return None

  with ThreadPoolExecutor(len(calls)) as pool:
    return list(pool.map(one, calls))


def test_distinct_ids_answer_and_free_the_port():
  port = _free_port()
  t0 = time.monotonic()
  assert _roll_call([(3, 0), (3, 2), (3, 1)], port=port) == [None, None, None]
  assert time.monotonic() - t0 < 3.0
  with socket.create_server(("", port)):  # the port is free for JAX's service
    pass


def test_a_repeated_id_stops_every_process_at_once_naming_the_variable():
  t0 = time.monotonic()
  errors = _roll_call([(3, 0), (3, 1), (3, 1)])
  assert time.monotonic() - t0 < 3.0  # not the timeout
  for e in errors:
    assert isinstance(e, roll_call.RollCallError)
    assert "two processes have MFSAMPLE_PROCESS_ID=1" in str(e) and "\n" not in str(e)
    assert "give each process its own id, 0 .. 2" in str(e)


def test_two_processes_with_id_0_on_one_machine_both_stop():
  errors = _roll_call([(2, 0), (2, 0)])
  messages = sorted(str(e) for e in errors)
  assert messages[0].startswith("process 0 cannot listen on port") and (
      "another process with MFSAMPLE_PROCESS_ID=0" in messages[0])
  assert messages[1].startswith("two processes have MFSAMPLE_PROCESS_ID=0")


def test_counts_that_differ_stop_every_process():
  errors = _roll_call([(2, 0), (3, 1)])
  for e in errors:
    assert "MFSAMPLE_NUM_PROCESSES differs between processes: 3 in process 1" in str(e)


def test_a_missing_process_is_named_after_the_timeout():
  t0 = time.monotonic()
  errors = _roll_call([(4, 0), (4, 2)], timeout=1.0)
  assert 1.0 <= time.monotonic() - t0 < 4.0
  for e in errors:  # process 2 hears process 0's verdict
    assert str(e).startswith("processes [1, 3] (MFSAMPLE_PROCESS_ID) did not reach process 0 "
                             "within MFSAMPLE_INIT_TIMEOUT = 5 s")


def test_without_process_0_a_process_stops_after_the_timeout():
  port = _free_port()
  (error,) = _roll_call([(2, 1)], timeout=0.5, port=port)
  assert f"process 0 did not answer at localhost:{port} (JAX_COORDINATOR_ADDRESS)" in str(error)


def test_a_process_too_many_is_told_so():
  """After the roll call the port belongs to JAX's service, which hangs up on a line of JSON:
  a late process with a repeated id learns it is one too many."""
  port = _free_port()
  assert _roll_call([(2, 0), (2, 1)], port=port) == [None, None]
  with socket.create_server(("", port)) as service:
    def hang_up():
      conn, _ = service.accept()
      conn.recv(100)
      conn.close()

    thread = threading.Thread(target=hang_up)
    thread.start()
    (error,) = _roll_call([(2, 1)], port=port)
    thread.join()
  assert "had already heard from all 2 processes (MFSAMPLE_PROCESS_ID=1 given twice" in str(error)


def test_a_stray_connection_does_not_disturb_the_roll_call():
  port = _free_port()

  def stray():
    time.sleep(0.05)
    with socket.create_connection(("localhost", port)) as conn:
      conn.sendall(b"GET / HTTP/1.0\r\n\r\n")

  thread = threading.Thread(target=stray)
  thread.start()
  assert _roll_call([(2, 0), (2, 1)], port=port) == [None, None]
  thread.join()


def test_an_unknown_host_is_named_at_once():
  for pid in (0, 1):
    with pytest.raises(roll_call.RollCallError, match=r"JAX_COORDINATOR_ADDRESS: the host "
                                                      r"'nosuchhost.invalid' cannot be resolved"):
      roll_call.call("nosuchhost.invalid", 1234, 2, pid, 5.0, NAMES)
