"""Ctrl-C and SIGTERM stop a run at a safe point, leaving a workdir that resumes.

A signal that arrives while JAX runs compiled code or compiles it must not unwind the stack
there (Python's default KeyboardInterrupt can then end the process with a segmentation
fault). Inside `stop_at_safe_points()` (every experiment's command line runs in it) SIGINT
and SIGTERM only record the request; the training loop and the experiments call `check()`
between steps and units of work, which raises `Interrupted` there, after the step in progress
(the training loop first writes a checkpoint). A second Ctrl-C raises KeyboardInterrupt at
once, for a user who does not want to wait.

Outside it (a notebook, a library call) nothing changes: Ctrl-C is Python's
KeyboardInterrupt.
"""

import contextlib
import signal
import threading

# Exit codes of a process ended by a signal, as shells report them: 128 + the signal number.
EXIT_CODES = {signal.SIGINT: 130, signal.SIGTERM: 143}

_requested = []  # the signals received inside `stop_at_safe_points`, in order


class Interrupted(Exception):
  """A run stopped at a safe point on a signal (SIGINT or SIGTERM).

  Attributes:
    signum: the signal.
  """

  def __init__(self, signum, where=""):
    self.signum = signum
    name = signal.Signals(signum).name
    super().__init__(f"stopped on {name}" + (f" {where}" if where else ""))

  @property
  def exit_code(self):
    return EXIT_CODES.get(self.signum, 128 + int(self.signum))


def requested():
  """The first signal received inside `stop_at_safe_points`, or None."""
  return _requested[0] if _requested else None


def check(where=""):
  """Raises `Interrupted` if a stop was requested (a safe point: between steps or units)."""
  if _requested:
    raise Interrupted(_requested[0], where)


@contextlib.contextmanager
def stop_at_safe_points(on_request=None):
  """Within the block, SIGINT and SIGTERM request a stop at the next `check()`.

  Args:
    on_request: optional callback(signum) on the first signal (a message to the user).
  """
  if threading.current_thread() is not threading.main_thread():
    yield  # signal handlers can only be installed from the main thread
    return

  def handler(signum, frame):
    del frame
    if _requested and signum == signal.SIGINT:
      raise KeyboardInterrupt  # the second Ctrl-C: stop now
    if not _requested:
      _requested.append(signum)
      if on_request is not None:
        on_request(signum)

  previous = {s: signal.signal(s, handler) for s in EXIT_CODES}
  try:
    yield
  finally:
    for s, h in previous.items():
      signal.signal(s, h)
    _requested.clear()
