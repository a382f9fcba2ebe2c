"""A roll call of the processes of one run before `jax.distributed` starts.

JAX's coordination service meets a process id given twice with a C++ abort (exit 134, after
up to the init timeout: "ALREADY_EXISTS ... newer incarnation"), and a run with too few or
too many processes with a deadline error. So, when the settings are given explicitly, process
0 first listens on the coordinator's port itself; every other process connects and sends its
id and process count; process 0 answers all of them at once, once it has heard from every id,
or as soon as two processes give the same id or the counts disagree. Then process 0 closes
the port and `jax.distributed` starts on it. Every process raises the same one-line
`DistributedError` naming the variable to fix (`mfsample.distributed` names them):

* two processes with one id (`MFSAMPLE_PROCESS_ID`): at once, when the second one calls in;
  two processes with id 0 on one machine: the second cannot listen on the port and calls in;
* process counts that differ (`MFSAMPLE_NUM_PROCESSES`): at once;
* a process that never calls in: after the init timeout (`MFSAMPLE_INIT_TIMEOUT`), naming the
  missing ids; a process calling in after the roll call (one process too many) finds the port
  closed or held by JAX's service;
* an address whose host cannot be resolved (`JAX_COORDINATOR_ADDRESS`): at once.

Messages are single lines of JSON over TCP; nothing else is exchanged.
"""

import json
import os
import socket
import time

MESSAGE_BYTES = 4096  # the longest line read (a registration or an answer is ~100 bytes)
_RETRY_SECONDS = 0.2  # between attempts to reach process 0 while it is not listening yet
_REGISTRATION_SECONDS = 10.0  # for a caller to send its line (a stray connection is dropped)


class RollCallError(RuntimeError):
  """The processes of a run do not add up (a repeated id, counts that differ, one missing);
  the message names the variable to fix."""


def call(host, port, num_processes, process_id, timeout, names):
  """Takes part in the roll call; returns when every process has answered with a distinct id.

  Args:
    host, port: process 0's address (`JAX_COORDINATOR_ADDRESS`, already split).
    num_processes: this process's count of processes (> 1).
    process_id: this process's id, 0 .. num_processes - 1.
    timeout: seconds to wait for every process (or, in processes other than 0, for process 0).
    names: {"address", "num_processes", "process_id", "timeout"}: how the messages name the
      four settings (environment variables or arguments).

  Raises:
    RollCallError: naming the setting to fix (see the module docstring).
  """
  deadline = time.monotonic() + timeout
  if process_id == 0:
    try:  # the others, and JAX's client in this process, will connect to it
      socket.getaddrinfo(host, port)
    except socket.gaierror as e:
      raise RollCallError(f"{names['address']}: the host {host!r} cannot be resolved "
                          f"({e.strerror})") from None
    try:
      server = _listen(port)
    except OSError as e:
      # Most likely a second process 0 (or another program) holds the port: tell the first one,
      # so that it stops its run too, then stop.
      _report_duplicate_zero(host, port, num_processes)
      raise RollCallError(
          f"process 0 cannot listen on port {port} of {names['address']} ({e.strerror}): "
          f"another process with {names['process_id']}=0, or another program, holds it; give "
          f"{names['process_id']}=0 to one process and a free port in {names['address']}"
          ) from None
    with server:
      _chair(server, num_processes, deadline, names)
  else:
    _answer(host, port, num_processes, process_id, deadline, names)


def _listen(port):
  """A listening socket on every address of this machine at `port` (as JAX's service binds
  `[::]:port`), without SO_REUSEPORT: a second listener on the port fails."""
  if socket.has_dualstack_ipv6():
    return socket.create_server(("", port), family=socket.AF_INET6, dualstack_ipv6=True,
                                backlog=128)
  return socket.create_server(("", port), backlog=128)


def _chair(server, num_processes, deadline, names):
  """Process 0: collects one registration per id 1 .. n - 1, then answers every caller."""
  callers = {}  # process id -> (socket, "host pid")
  error = None
  try:
    while error is None and len(callers) < num_processes - 1:
      left = deadline - time.monotonic()
      if left <= 0:
        missing = [i for i in range(1, num_processes) if i not in callers]
        error = (f"processes {missing} ({names['process_id']}) did not reach process 0 within "
                 f"{names['timeout']}: start every process of the run, or raise the timeout")
        break
      server.settimeout(left)
      try:
        conn, _ = server.accept()
      except TimeoutError:
        continue
      conn.settimeout(_REGISTRATION_SECONDS)  # a process of the run sends at once
      try:
        note = json.loads(_read_line(conn))
        caller_id, caller_count = int(note["id"]), int(note["num_processes"])
        who = f"{note.get('host', '?')} pid {note.get('pid', '?')}"
      except (OSError, ValueError, KeyError, TypeError):
        conn.close()  # not a process of this run (a port scan, a stray connection)
        continue
      if caller_count != num_processes:
        error = (f"{names['num_processes']} differs between processes: {caller_count} in "
                 f"process {caller_id} ({who}), {num_processes} in process 0; give every "
                 "process the same count")
      elif caller_id == 0 or caller_id in callers:
        first = "process 0 (this one)" if caller_id == 0 else callers[caller_id][1]
        error = (f"two processes have {names['process_id']}={caller_id} ({first} and {who}); "
                 f"give each process its own id, 0 .. {num_processes - 1}")
      callers.setdefault(caller_id, (conn, who))
      if error is not None and callers[caller_id][0] is not conn:
        _send(conn, {"error": error})
        conn.close()
    answer = {"ok": True} if error is None else {"error": error}
    for conn, _ in callers.values():
      _send(conn, answer)
    for conn, _ in callers.values():  # let the callers close first (no TIME_WAIT on the port)
      try:
        conn.settimeout(2.0)
        conn.recv(1)
      except OSError:
        pass
  finally:
    for conn, _ in callers.values():
      conn.close()
  if error is not None:
    raise RollCallError(error)


def _answer(host, port, num_processes, process_id, deadline, names):
  """Every other process: registers with process 0 and waits for its answer."""
  note = {"id": process_id, "num_processes": num_processes, "host": socket.gethostname(),
          "pid": os.getpid()}
  while True:
    left = deadline - time.monotonic()
    try:
      conn = socket.create_connection((host, port), timeout=max(min(left, 5.0), 0.1))
      break
    except socket.gaierror as e:
      raise RollCallError(f"{names['address']}: the host {host!r} cannot be resolved "
                          f"({e.strerror})") from None
    except OSError:  # process 0 is not listening yet
      if left <= 0:
        raise RollCallError(
            f"process 0 did not answer at {host}:{port} ({names['address']}) within "
            f"{names['timeout']}: start process 0 ({names['process_id']}=0) on that host, or "
            "raise the timeout") from None
      time.sleep(min(_RETRY_SECONDS, max(left, 0.0)))
  with conn:
    try:
      _send(conn, note)
      conn.settimeout(max(deadline - time.monotonic(), 0.1))
      reply = json.loads(_read_line(conn))
    except (OSError, ValueError):
      # No answer, or not one of ours: process 0 already heard from every id and handed its
      # port to JAX's service (this process is one too many), or it failed.
      raise RollCallError(
          f"process 0 at {host}:{port} did not take process {process_id} into the run: it "
          f"had already heard from all {num_processes} processes "
          f"({names['process_id']}={process_id} given twice, or {names['num_processes']} too "
          "small?), or it stopped") from None
  if not isinstance(reply, dict) or reply.get("ok") is not True:
    message = reply.get("error") if isinstance(reply, dict) else None
    raise RollCallError(str(message or f"unexpected answer from process 0: {reply!r}"))


def _report_duplicate_zero(host, port, num_processes):
  """Tells the process 0 already listening that a second one exists (best effort)."""
  try:
    with socket.create_connection((host, port), timeout=2.0) as conn:
      _send(conn, {"id": 0, "num_processes": num_processes, "host": socket.gethostname(),
                   "pid": os.getpid()})
  except OSError:
    pass


def _send(conn, message):
  try:
    conn.sendall(json.dumps(message).encode("utf-8")[:MESSAGE_BYTES - 1] + b"\n")
  except OSError:
    pass  # a caller that went away learns nothing; the others still get the answer


def _read_line(conn):
  """One newline-terminated line (at most MESSAGE_BYTES); ValueError when the peer closes or
  sends something else first."""
  data = b""
  while not data.endswith(b"\n"):
    chunk = conn.recv(MESSAGE_BYTES - len(data))
    if not chunk:
      raise ValueError("connection closed")
    data += chunk
    if len(data) >= MESSAGE_BYTES:
      raise ValueError("line too long")
  return data.decode("utf-8")
