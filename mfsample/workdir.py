"""A workdir is written by one process at a time: its lock, and the errors of a workdir.

A job's workdir holds the results of one config (`mfsample.config_record` compares a call's
config with the workdir's `config.json` and refuses another). Two processes on one workdir
would mix or overwrite each other's results, so a run holds the workdir's lock (`locked`)
from before the guard until it ends: a second process is refused, naming the holder. The lock
is the kernel's (`fcntl.flock` on `workdir/.lock`): it goes with the process however the
process ends, so a lock file left by a killed run is taken over (with a warning naming that
run).
"""

import contextlib
import datetime
import errno
import fcntl
import json
import os
import socket
import warnings


class WorkdirError(ValueError):
  """A workdir holds results of a different (or unknown) config."""


class InputsChangedError(WorkdirError):
  """A workdir holds results computed from files that have changed since (named)."""


class WorkdirReadOnlyError(WorkdirError):
  """A call has to write into a workdir it may only read (a read-only mount or folder)."""


# What opening or creating a file says of a folder the process may not write.
_READ_ONLY = (errno.EACCES, errno.EPERM, errno.EROFS)


def differences(old, new, prefix=""):
  """Dotted paths of the leaves where two nested dicts differ."""
  if not (isinstance(old, dict) and isinstance(new, dict)):
    return [] if old == new else [prefix or "(root)"]
  out = []
  for key in sorted(set(old) | set(new)):
    path = f"{prefix}.{key}" if prefix else key
    if key not in old or key not in new:
      out.append(path)
    else:
      out += differences(old[key], new[key], path)
  return out


LOCK_FILE = ".lock"


class WorkdirBusyError(RuntimeError):
  """Another process holds the workdir (the message names it)."""


def _holder(path):
  """What a lock file says of the process that wrote it ("" when unreadable)."""
  try:
    with open(path, encoding="utf-8") as f:
      info = json.load(f)
    return (f"process {info['pid']} on {info['host']} ({info.get('what', 'a run')}, "
            f"started {info['started']})")
  except (OSError, ValueError, KeyError, TypeError):
    return ""


@contextlib.contextmanager
def locked(workdir, what="a run"):
  """Holds `workdir`'s lock for the block: one writer per workdir.

  Creates `workdir` if needed (and removes it again if the block leaves it empty, so that a
  refused call leaves no trace).

  Args:
    workdir: the folder.
    what: the holder's description in the message another process gets ("camera planning").

  Raises:
    WorkdirBusyError: a live process holds it (naming the process, its host and its job).
    WorkdirReadOnlyError: the folder (or its parent, to create it) may not be written: no
      writer can hold it, and none can write it.
  """
  created = not os.path.isdir(workdir)
  path = os.path.join(workdir, LOCK_FILE)
  try:
    os.makedirs(workdir, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
  except OSError as e:
    if e.errno not in _READ_ONLY:
      raise
    raise WorkdirReadOnlyError(
        f"{workdir} is read-only ({e.strerror}): {what} cannot write there; make it "
        "writable, or use another --workdir") from None
  while True:
    try:
      fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as e:
      if e.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
        warnings.warn(f"{workdir}: its file system has no locks; a second process on it "
                      "would not be detected", stacklevel=3)
        break
      os.close(fd)
      if e.errno not in (errno.EAGAIN, errno.EACCES):
        raise
      holder = _holder(path) or "another process"
      raise WorkdirBusyError(
          f"{workdir} is in use by {holder}: wait for it to end, or use another "
          "--workdir") from None
    # The file may have been removed and recreated by a releasing holder between our open and
    # our lock: then our lock is on a file nobody else sees; start again.
    try:
      same = os.fstat(fd).st_ino == os.stat(path).st_ino
    except FileNotFoundError:
      same = False
    if same:
      break
    os.close(fd)
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
  stale = _holder(path)
  if stale:
    warnings.warn(f"{workdir}: taking over from {stale}, which ended without releasing it",
                  stacklevel=3)
  info = {"pid": os.getpid(), "host": socket.gethostname(), "what": what,
          "started": datetime.datetime.now().isoformat(timespec="seconds")}
  os.ftruncate(fd, 0)
  os.write(fd, json.dumps(info).encode("utf-8"))
  os.fsync(fd)
  try:
    yield
  finally:
    # Removed while still held, so the next holder finds no stale record; only if the path is
    # still this lock's file (a user may have removed the workdir meanwhile).
    with contextlib.suppress(FileNotFoundError):
      if os.stat(path).st_ino == os.fstat(fd).st_ino:
        os.remove(path)
    os.close(fd)
    with contextlib.suppress(OSError):
      if created and not os.listdir(workdir):
        os.rmdir(workdir)
