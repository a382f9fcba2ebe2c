"""A command run with a folder it may only read, as on a read-only mount.

Without root, the folder's write permissions are taken away for the command (`chmod -R
a-w`) and given back after. Root writes whatever the permissions say, so there the folder is
bind-mounted read-only over itself in a mount namespace of the command's own (`unshare -m`);
where that is not allowed either, the test is skipped.
"""

import os
import shutil
import stat
import subprocess

import pytest


def _chmod_tree(root, writable):
  for folder, dirs, files in os.walk(root):
    for name in [folder] + [os.path.join(folder, n) for n in dirs + files]:
      mode = os.stat(name).st_mode
      bits = stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH
      os.chmod(name, (mode | stat.S_IWUSR) if writable else (mode & ~bits))


def run_read_only(folder, argv, **kwargs):
  """`subprocess.run(argv, **kwargs)` while `folder` (and everything in it) is read-only."""
  folder = os.fspath(folder)
  kwargs.setdefault("capture_output", True)
  kwargs.setdefault("text", True)
  if os.geteuid() != 0:
    _chmod_tree(folder, writable=False)
    try:
      return subprocess.run(argv, **kwargs)
    finally:
      _chmod_tree(folder, writable=True)
  if shutil.which("unshare") is None:
    pytest.skip("root without unshare: no read-only folder to test with")
  script = 'mount --bind "$0" "$0" && mount -o remount,bind,ro "$0" "$0" && exec "$@"'
  probe = subprocess.run(["unshare", "-m", "sh", "-c", script, folder, "true"],
                         capture_output=True, text=True)
  if probe.returncode != 0:
    pytest.skip(f"root cannot make a read-only mount here: {probe.stderr.strip()}")
  return subprocess.run(["unshare", "-m", "sh", "-c", script, folder, *argv], **kwargs)
