"""The job skeleton: validation before the guard, checked reads, atomic writes, progress."""

import json
import os

import ml_collections
import numpy as np
import pytest

from mfsample import jobs
from mfsample import workdir as workdir_lib
from mfsample.config_checks import ConfigError, check_int
from mfsample.workdir import WorkdirError


def _config(steps=3):
  config = ml_collections.ConfigDict()
  config.steps = steps
  config.progress = False
  return config


def _validate(config):
  check_int(config, "steps", minimum=1)


def _run(config, workdir):
  with jobs.open_workdir(JOB, config, workdir) as wd:
    wd.write_config()
    done = wd.read_json("runs/a.json")
    if done is None:
      done = {"value": int(config.steps) * 2}
      wd.write_json("runs/a.json", done)
    return done


JOB = jobs.Job("toy", "toy", _run, _validate, free_fields=("progress",), results=("runs",))


def test_a_bad_config_is_refused_before_the_workdir_is_touched(tmp_path):
  with pytest.raises(ConfigError, match="config.steps = 0"):
    _run(_config(0), str(tmp_path / "w"))
  assert not (tmp_path / "w").exists()


def test_results_of_another_config_are_refused_and_free_fields_may_differ(tmp_path):
  workdir = str(tmp_path / "w")
  assert _run(_config(3), workdir) == {"value": 6}
  other = _config(3)
  other.progress = True  # a free field
  assert _run(other, workdir) == {"value": 6}
  with pytest.raises(WorkdirError, match=r"differences: steps\)"):
    _run(_config(4), workdir)


def test_a_damaged_record_is_reported_by_name_and_computed_again(tmp_path):
  workdir = tmp_path / "w"
  _run(_config(3), str(workdir))
  (workdir / "runs" / "a.json").write_text('{"value": 6')  # truncated
  with pytest.warns(UserWarning, match=r"runs/a\.json is damaged"):
    assert _run(_config(3), str(workdir)) == {"value": 6}
  assert json.loads((workdir / "runs" / "a.json").read_text()) == {"value": 6}
  (workdir / "runs" / "a.json").write_text("[1, 2]")  # JSON, but not a record
  with pytest.warns(UserWarning, match="not a JSON object"):
    _run(_config(3), str(workdir))


def test_arrays_are_written_whole_and_damaged_ones_read_as_missing(tmp_path):
  wd = jobs.Workdir(JOB, _config(), str(tmp_path))
  wd.save_arrays("a/x.npz", pred=np.arange(4.0))
  assert sorted(os.listdir(tmp_path / "a")) == ["x.npz"]  # no temporary left
  np.testing.assert_array_equal(wd.load_arrays("a/x.npz", keys=("pred",))["pred"],
                                np.arange(4.0))
  assert wd.load_arrays("a/missing.npz") is None
  with pytest.warns(UserWarning, match=r"missing \['other'\]"):
    assert wd.load_arrays("a/x.npz", keys=("pred", "other")) is None
  data = (tmp_path / "a" / "x.npz").read_bytes()
  (tmp_path / "a" / "x.npz").write_bytes(data[: len(data) // 2])
  with pytest.warns(UserWarning, match=r"a/x\.npz is damaged"):
    assert wd.load_arrays("a/x.npz", keys=("pred",)) is None


def test_progress_bars_follow_the_jobs_flag(tmp_path):
  config = _config()
  assert jobs.Workdir(JOB, config, str(tmp_path)).progress(3).disable
  config.progress = True
  bar = jobs.Workdir(JOB, config, str(tmp_path)).progress(3)
  assert not bar.disable
  bar.close()


def test_a_process_other_than_the_first_reads_the_workdir_and_writes_nothing(tmp_path,
                                                                               monkeypatch):
  """In a multi-process run (`mfsample.distributed`) only process 0 writes: the others take
  no lock, write no config, record, array or checkpoint, and read what process 0 wrote."""
  from mfsample import distributed
  from mfsample.train import checkpoint as ckpt

  workdir = tmp_path / "w"
  assert _run(_config(), str(workdir)) == {"value": 6}  # process 0's earlier run
  before = {p: p.read_bytes() for p in workdir.rglob("*") if p.is_file()}
  monkeypatch.setattr(distributed, "is_writer", lambda: False)
  with jobs.open_workdir(JOB, _config(), str(workdir)) as wd:
    assert not wd.writes and not (workdir / ".lock").exists()
    assert wd.read_json("runs/a.json") == {"value": 6}
    wd.write_config()
    wd.write_json("runs/b.json", {"x": 1})
    wd.write_text("table.md", "x")
    wd.save_arrays("arrays.npz", a=np.zeros(2))
    path = ckpt.save_checkpoint(wd.file("checkpoints"), {"w": np.ones(2)}, {"step": 1})
    assert path.endswith("ckpt_00000001.npz")
    assert wd.progress(3).disable
  after = {p: p.read_bytes() for p in workdir.rglob("*") if p.is_file()}
  assert after == before
  fresh = tmp_path / "fresh"
  with jobs.open_workdir(JOB, _config(), str(fresh)) as wd:
    wd.write_config()
  assert not fresh.exists()


# ------------------------------------------------------------------ inputs and pointed files


def _reader_config(path, policy="stop"):
  config = ml_collections.ConfigDict()
  config.data = ml_collections.ConfigDict({"path": str(path), "inputs_changed": policy})
  return config


COMPUTED = []


def _read_and_point(config, workdir):
  """Reads a JSON input (as a loader does) and writes a record pointing to a folder."""
  from mfsample.data import _io

  with jobs.open_workdir(READER, config, workdir) as wd:
    done = wd.read_json("runs/a.json")
    if done is not None:
      return done
    value = _io.read_json(config.data.path)["v"]
    wd.write_config()
    COMPUTED.append(value)
    if wd.writes:
      os.makedirs(wd.file("out"), exist_ok=True)
      with open(wd.file("out", "x.txt"), "w") as f:
        f.write(str(value))
    done = {"value": value}
    wd.write_json("runs/a.json", done, files=("out",))
    return done


READER = jobs.Job("reader", "reader", _read_and_point, lambda config: None, free_fields=(),
                  results=("runs",))


def test_a_rerun_whose_inputs_changed_stops_naming_them_or_recomputes(tmp_path):
  source, workdir = tmp_path / "input.json", str(tmp_path / "w")
  source.write_text('{"v": 1}')
  COMPUTED.clear()
  assert _read_and_point(_reader_config(source), workdir) == {"value": 1}
  recorded = json.loads((tmp_path / "w" / "inputs.json").read_text())["files"]
  assert list(recorded) == [str(source)] and recorded[str(source)]["size"] == 8
  assert _read_and_point(_reader_config(source), workdir) == {"value": 1}
  source.write_text('{"v": 22}')
  with pytest.raises(WorkdirError, match=rf"computed from files that have changed since: "
                     rf"{source}: size 8 -> 9 bytes, .*--config.data.inputs_changed="):
    _read_and_point(_reader_config(source), workdir)
  source.write_text('{"v": 2}')  # same size: the content hash tells
  with pytest.raises(workdir_lib.InputsChangedError, match=r"input.json: .*sha256 "):
    _read_and_point(_reader_config(source), workdir)
  assert COMPUTED == [1]  # stopped before anything was computed
  with pytest.raises(ConfigError, match="config.data.inputs_changed = 'ignore'"):
    _read_and_point(_reader_config(source, "ignore"), workdir)
  with pytest.warns(UserWarning, match=r"input.json: .*computing them again"):
    assert _read_and_point(_reader_config(source, "recompute"), workdir) == {"value": 2}
  assert COMPUTED == [1, 2]
  assert _read_and_point(_reader_config(source), workdir) == {"value": 2}  # now recorded
  source.write_text('{"v": 1}')  # the first input's bytes again: its results are not kept
  with pytest.raises(workdir_lib.InputsChangedError):
    _read_and_point(_reader_config(source), workdir)
  source.unlink()
  with pytest.raises(workdir_lib.InputsChangedError, match="input.json: removed"):
    _read_and_point(_reader_config(source), workdir)


def test_inputs_of_a_workdir_without_results_are_not_checked(tmp_path):
  source, workdir = tmp_path / "input.json", tmp_path / "w"
  source.write_text('{"v": 1}')
  _read_and_point(_reader_config(source), str(workdir))
  import shutil

  shutil.rmtree(workdir / "runs")  # a stale record beside no results is replaced
  source.write_text('{"v": 3}')
  assert _read_and_point(_reader_config(source), str(workdir)) == {"value": 3}
  (workdir / "inputs.json").write_text("{")
  with pytest.raises(WorkdirError, match=r"inputs.json is unreadable"):
    _read_and_point(_reader_config(source), str(workdir))


def test_a_record_is_read_back_only_while_the_files_it_points_to_are_unchanged(tmp_path):
  source, workdir = tmp_path / "input.json", tmp_path / "w"
  source.write_text('{"v": 5}')
  COMPUTED.clear()
  _read_and_point(_reader_config(source), str(workdir))
  record = json.loads((workdir / "runs" / "a.json").read_text())
  assert list(record[jobs.FILES_KEY]) == [os.path.join("out", "x.txt")]
  assert _read_and_point(_reader_config(source), str(workdir)) == {"value": 5}  # key hidden
  for damage in (lambda p: p.write_text("6"), lambda p: p.unlink(),
                 lambda p: p.parent.rename(p.parent.with_name("gone"))):
    damage(workdir / "out" / "x.txt")
    with pytest.warns(UserWarning, match=r"runs/a\.json points to files that are no longer "
                      r"what it wrote \(.*out/x\.txt: "):
      assert _read_and_point(_reader_config(source), str(workdir)) == {"value": 5}
    assert (workdir / "out" / "x.txt").read_text() == "5"
  assert COMPUTED == [5, 5, 5, 5]


_READ_ONLY_CALLS = """
import json, sys
sys.path.insert(0, sys.argv[1])
from test_jobs import _read_and_point, _reader_config
for workdir, policy in json.loads(sys.argv[2]):
  try:
    print("result", _read_and_point(_reader_config(sys.argv[3], policy), workdir))
  except Exception as e:
    print(type(e).__name__, e)
"""


def test_a_read_only_workdir_is_read_and_a_call_that_must_write_it_is_refused(tmp_path):
  """On a read-only mount a finished workdir is read back without the lock; a call that has
  something to write stops with one line naming the workdir."""
  import shutil
  import sys

  from readonly_testlib import run_read_only

  source = tmp_path / "input.json"
  source.write_text('{"v": 7}')
  root = tmp_path / "mount"
  for name in ("done", "unfinished", "changed"):
    _read_and_point(_reader_config(source), str(root / name))
  shutil.rmtree(root / "unfinished" / "runs")
  other = tmp_path / "other.json"
  other.write_text('{"v": 8}')
  (root / "changed" / "inputs.json").write_text(
      (root / "changed" / "inputs.json").read_text().replace(str(source), str(other)))
  calls = [(str(root / "done"), "stop"), (str(root / "unfinished"), "stop"),
           (str(root / "changed"), "recompute"), (str(root / "new"), "stop")]
  before = sorted(str(p) for p in root.rglob("*"))
  other.write_text('{"v": 9}')
  out = run_read_only(root, [sys.executable, "-c", _READ_ONLY_CALLS, os.path.dirname(__file__),
                             json.dumps(calls), str(source)], cwd=str(tmp_path))
  lines = out.stdout.strip().splitlines()
  assert out.returncode == 0 and len(lines) == 4, out.stdout + out.stderr
  assert lines[0] == "result {'value': 7}"
  assert lines[1] == (f"WorkdirReadOnlyError {root / 'unfinished'} is read-only, and this "
                      "reader call has results to compute and write (config.json): make it "
                      "writable, or use another --workdir")
  assert lines[2].startswith(f"WorkdirReadOnlyError {root / 'changed'} is read-only, and its "
                             f"reader results are to be computed again (their inputs changed: "
                             f"{other}: ")
  assert lines[3].startswith(f"WorkdirReadOnlyError {root / 'new'} is read-only (")
  assert sorted(str(p) for p in root.rglob("*")) == before  # not even a lock file


# A job whose run initialises JAX's backend (the platform probe) and then meets bad input.
_PROBING_JOB = """
import sys
from mfsample import jobs
from mfsample.data import DatasetError

def run(config, workdir):
  import logging
  import jax
  jax.devices()
  logging.getLogger("mfsample.data.downscaled").warning("/data: made images_8/")
  raise DatasetError("/data/x.json: 'fl_x' must be a finite number, got 'a'.")

jobs.main(jobs.Job("toy", "toy", run, lambda c: None, free_fields=(), results=()))
"""


@pytest.mark.parametrize("verbose", [False, True])
def test_main_reports_bad_input_in_one_line_and_no_platform_probe(tmp_path, verbose):
  import subprocess
  import sys

  config = tmp_path / "config.py"
  config.write_text("import ml_collections\n\ndef get_config():\n"
                    "  return ml_collections.ConfigDict({'progress': True})\n")
  args = [f"--config={config}", f"--workdir={tmp_path / 'w'}"] + ["--verbose"] * verbose
  out = subprocess.run([sys.executable, "-c", _PROBING_JOB, *args], capture_output=True,
                       text=True, timeout=120)
  lines = out.stderr.strip().splitlines()
  assert "Unable to initialize backend" not in out.stderr  # JAX's INFO probe lines
  assert lines[0] == f"toy: starting (workdir {tmp_path / 'w'})"
  if verbose:
    assert out.returncode == 1 and "Traceback" in out.stderr
    assert lines[-1].endswith("'fl_x' must be a finite number, got 'a'.")
  else:
    assert out.returncode == 2 and lines[1:] == [
        "toy: /data: made images_8/",  # the package's log lines: plain, one each
        "toy: DatasetError: /data/x.json: 'fl_x' must be a finite number, got 'a'. "
        "(--verbose shows the traceback)"], out.stderr
