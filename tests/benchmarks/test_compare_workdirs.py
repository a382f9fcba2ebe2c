"""benchmarks/compare_workdirs.py: two workdirs' results compared bit for bit."""

import json
import subprocess
import sys

import numpy as np
from bench_testlib import import_script

compare, DEFAULTS = import_script("compare_workdirs")


def write_run(path, *, loss=0.5, seconds=1.0, weights=(1.0, 2.0), meta_kind="lowrank",
              key="params.b_hat"):
  """A workdir of one JSON result, one checkpoint and a config.json."""
  path.mkdir()
  (path / "config.json").write_text(json.dumps({"seed": int(seconds)}))
  (path / "metrics.json").write_text(json.dumps(
      {"loss": loss, "nan": float("nan"), "seconds": seconds, "rows": [{"psnr": 20.0}]}))
  np.savez(path / "ckpt.npz", **{key: np.array(weights, np.float32),
                                 "__meta__": np.array(json.dumps({"kind": meta_kind,
                                                                  "seconds": seconds}))})


def test_equal_runs_differ_only_in_what_the_machine_measures(tmp_path):
  write_run(tmp_path / "a", seconds=1.0)
  write_run(tmp_path / "b", seconds=7.0)  # wall-clock and config.json are not results
  assert compare.compare_workdirs(tmp_path / "a", tmp_path / "b",
                                  skip=DEFAULTS["skip"]) == (2, [])


def test_every_kind_of_difference_is_named(tmp_path):
  write_run(tmp_path / "a")
  write_run(tmp_path / "b", loss=0.25, weights=(1.0, np.nextafter(np.float32(2), 3)),
            meta_kind="block")
  (tmp_path / "a" / "extra.json").write_text("{}")
  compared, differences = compare.compare_workdirs(tmp_path / "a", tmp_path / "b",
                                                   skip=DEFAULTS["skip"])
  assert compared == 2
  assert sorted(differences) == [
      "ckpt.npz:__meta__.kind: 'lowrank' in A, 'block' in B",
      "ckpt.npz:params.b_hat: differs",  # one float32 ulp is a difference
      "extra.json: not in B",
      "metrics.json.loss: 0.5 in A, 0.25 in B"]


def test_renamed_arrays_are_compared_under_their_new_name(tmp_path):
  write_run(tmp_path / "a", key="params.spread")
  write_run(tmp_path / "b")
  assert compare.compare_workdirs(tmp_path / "a", tmp_path / "b", skip=DEFAULTS["skip"]) == (
      2, ["ckpt.npz:params.spread: not in B"])
  assert compare.compare_workdirs(tmp_path / "a", tmp_path / "b", skip=DEFAULTS["skip"],
                                  renames=[(".spread", ".b_hat")]) == (2, [])


def test_the_command_line_exits_1_on_a_difference(tmp_path):
  write_run(tmp_path / "a")
  write_run(tmp_path / "b", loss=0.25)
  script = "benchmarks/compare_workdirs.py"
  same = subprocess.run([sys.executable, script, str(tmp_path / "a"), str(tmp_path / "a")],
                        capture_output=True, text=True)
  assert same.returncode == 0 and same.stdout.startswith("2 files compared; 0 differences")
  other = subprocess.run([sys.executable, script, str(tmp_path / "a"), str(tmp_path / "b")],
                         capture_output=True, text=True)
  assert other.returncode == 1 and "metrics.json.loss" in other.stdout
  missing = subprocess.run([sys.executable, script, str(tmp_path / "a"), "nowhere"],
                           capture_output=True, text=True)
  assert missing.returncode != 0 and "nowhere: not a folder" in missing.stderr
