"""Ctrl-C and SIGTERM stop a run between steps; the workdir resumes to the same result."""

import os
import signal
import subprocess
import sys
import time

import jax
import numpy as np
import pytest
from conftest import tiny_config, train_with

from mfsample import interrupts
from mfsample.train import loop

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


@pytest.mark.parametrize("sigint_before", ["as started", "ignored"])
def test_a_signal_is_a_request_checked_at_safe_points(sigint_before):
  # Whatever handlers the process started with (a shell's `&` leaves SIGINT ignored), the
  # block restores them.
  started_with = signal.getsignal(signal.SIGINT)
  if sigint_before == "ignored":
    signal.signal(signal.SIGINT, signal.SIG_IGN)
  before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
  try:
    with interrupts.stop_at_safe_points():
      interrupts.check()  # nothing requested
      os.kill(os.getpid(), signal.SIGTERM)
      assert interrupts.requested() == signal.SIGTERM
      with pytest.raises(interrupts.Interrupted, match="stopped on SIGTERM at step 3") as e:
        interrupts.check("at step 3")
      assert e.value.exit_code == 143
    interrupts.check()  # the request ends with the block
    assert {s: signal.getsignal(s) for s in before} == before
  finally:
    signal.signal(signal.SIGINT, started_with)


def test_a_second_ctrl_c_stops_at_once():
  with interrupts.stop_at_safe_points(), pytest.raises(KeyboardInterrupt):
    os.kill(os.getpid(), signal.SIGINT)
    assert interrupts.requested() == signal.SIGINT
    os.kill(os.getpid(), signal.SIGINT)


@pytest.mark.slow
def test_training_stopped_by_a_signal_checkpoints_and_resumes_bit_for_bit(tiny_dataset,
                                                                          tmp_path,
                                                                          monkeypatch):
  config = tiny_config("lowrank")
  reference = train_with(config, tiny_dataset)
  view_for_step = loop.view_for_step

  def signalled_at_step_13(seed, step, num_views):
    if step == 13:
      os.kill(os.getpid(), signal.SIGINT)  # as Ctrl-C during step 13
    return view_for_step(seed, step, num_views)

  monkeypatch.setattr(loop, "view_for_step", signalled_at_step_13)
  directory = str(tmp_path / "ckpt")
  with interrupts.stop_at_safe_points(), pytest.raises(interrupts.Interrupted,
                                                       match="at step 14"):
    train_with(config, tiny_dataset, checkpoint_dir=directory)
  assert sorted(os.listdir(directory))[-1] == "ckpt_00000014.npz"  # step 13 was finished
  monkeypatch.setattr(loop, "view_for_step", view_for_step)
  resumed = train_with(config, tiny_dataset, checkpoint_dir=directory)
  for a, b in zip(jax.tree.leaves(reference.state), jax.tree.leaves(resumed.state), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.slow
def test_the_command_line_exits_130_with_how_to_resume(tmp_path):
  workdir = tmp_path / "run"
  env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
  cmd = [sys.executable, "experiments/train.py", "--config=configs/train.py:tiny",
         f"--workdir={workdir}", "--config.train.num_steps=100000"]
  proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True)
  deadline = time.time() + 600
  while not (workdir / ".lock").exists():  # the run holds its workdir: handlers are in place
    assert proc.poll() is None and time.time() < deadline, proc.communicate()
    time.sleep(0.2)
  proc.send_signal(signal.SIGINT)
  _, err = proc.communicate(timeout=600)
  assert proc.returncode == 130, err[-2000:]
  assert "run the same command again to resume" in err
  assert "Traceback" not in err and "Segmentation fault" not in err
  assert not (workdir / ".lock").exists()
