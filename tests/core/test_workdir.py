"""One writer per workdir: a second process is refused by name; a dead one's lock is taken."""

import json
import os
import subprocess
import sys

import pytest

from mfsample import workdir as workdir_lib


def test_a_second_holder_is_refused_naming_the_first(tmp_path):
  workdir = str(tmp_path / "run")
  with workdir_lib.locked(workdir, "camera planning"):
    with pytest.raises(workdir_lib.WorkdirBusyError,
                       match=rf"in use by process {os.getpid()} on .*\(camera planning"):
      with workdir_lib.locked(workdir, "training"):
        pass
  assert not os.path.exists(workdir)  # created for the lock only: removed with it
  os.makedirs(workdir)
  with workdir_lib.locked(workdir):
    pass
  assert os.listdir(workdir) == []


def test_another_process_is_refused_and_its_lock_goes_with_it(tmp_path):
  workdir = tmp_path / "run"
  holder = subprocess.Popen(
      [sys.executable, "-c", "import sys, time; from mfsample import workdir as w\n"
       "with w.locked(sys.argv[1], 'light planning'):\n  print('held', flush=True)\n"
       "  time.sleep(600)", str(workdir)], stdout=subprocess.PIPE, text=True)
  try:
    assert holder.stdout.readline().strip() == "held"
    with pytest.raises(workdir_lib.WorkdirBusyError,
                       match=rf"process {holder.pid} on .*light planning"):
      with workdir_lib.locked(str(workdir)):
        pass
  finally:
    holder.kill()  # as kill -9: no clean release
    holder.wait()
  with pytest.warns(UserWarning, match=rf"taking over from process {holder.pid}"):
    with workdir_lib.locked(str(workdir)):
      info = json.loads((workdir / ".lock").read_text())
      assert info["pid"] == os.getpid()
  assert not (workdir / ".lock").exists()


def test_a_workdir_removed_during_the_run_ends_it_cleanly(tmp_path):
  import shutil

  workdir = str(tmp_path / "run")
  with workdir_lib.locked(workdir):
    shutil.rmtree(workdir)  # the user deleted it; another run may even hold it now
    os.makedirs(workdir)
    with workdir_lib.locked(workdir):
      pass
  assert not os.path.exists(workdir)
