"""`benchmarks/final_training.py` end to end on a tiny planning run (a subprocess: absl flags).

The README's longer-final-training figures come from this script, so what its docstring
promises is checked here: the first initialisation at the run's own final length reproduces
the run's metrics (it is the same protocol), a second call on the same --out trains nothing,
and --reuse_rows_from takes another file's rows instead of training them again.
"""

import json

import planning_testlib
import pytest


def _final_training(*args, check=True):
  return planning_testlib.run_benchmark("final_training", *args, check=check)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
  """Two strategies that train no round model (cheap), one seed, the tiny protocol."""
  return planning_testlib.tiny_run(tmp_path_factory.mktemp("run"))


def test_final_training_reproduces_the_run_and_resumes(tiny_run, tmp_path):
  results = json.loads(tiny_run.read_text())
  run_steps = int(results["final_steps"])
  out = tmp_path / "final.json"
  flags = [f"--results={tiny_run}", f"--steps={run_steps},{run_steps + 4}", "--views=2,3",
           "--references=farthest", f"--out={out}"]
  printed = _final_training(*flags).stdout
  record = json.loads(out.read_text())
  rows = record["rows"]
  assert len(rows) == 2 * 2 * 2  # strategies x view counts x lengths, one initialisation
  assert not any(r["from_run_record"] for r in rows)
  # Trained again at the run's length from its seed, a final model is the run's own.
  assert record["max_reproduction_error_db"] < 1e-3
  for run in results["runs"]:
    for n in (2, 3):
      row, = [r for r in rows if (r["strategy"], r["seed"], r["views"], r["steps"])
              == (run["strategy"], run["seed"], n, run_steps)]
      assert row["ssim"] == pytest.approx(run["metrics"][str(n)]["ssim"], abs=1e-4)
  assert f"trained for {out}: 8 models" in printed
  assert set(record["summary"]) == {str(run_steps), str(run_steps + 4)}
  # Paired with farthest point by seed: the difference of the two rows.
  paired = record["summary"][str(run_steps)]["3"]["paired_psnr"]["farthest"]["random"]["3"]
  psnr = {r["strategy"]: r["psnr"] for r in rows if r["views"] == 3 and r["steps"] == run_steps}
  assert paired["values"] == [pytest.approx(psnr["random"] - psnr["farthest"])]

  # The same call again finds every row done.
  _final_training(*flags)
  assert json.loads(out.read_text())["rows"] == rows

  # Another file takes the longer models from the first instead of training them again.
  other = tmp_path / "other.json"
  printed = _final_training(f"--results={tiny_run}", f"--steps={run_steps + 4}", "--views=3",
                            f"--reuse_rows_from={out}", f"--out={other}").stdout
  assert "2 rows reused" in printed and "trained for" not in printed
  reused = json.loads(other.read_text())["rows"]
  assert all(r["reused_from"] == str(out) for r in reused)
  assert [r["psnr"] for r in reused] == [r["psnr"] for r in rows
                                          if r["steps"] == run_steps + 4 and r["views"] == 3]


def test_final_training_judges_only_the_seeds_asked_for(tiny_run, tmp_path):
  out = tmp_path / "final.json"
  common = [f"--results={tiny_run}", "--steps=4", "--views=2", f"--out={out}"]
  _final_training(*common, "--seeds=0:1")  # The tiny run's one seed.
  assert {r["seed"] for r in json.loads(out.read_text())["rows"]} == {0}
  proc = _final_training(*common, "--seeds=1:3", check=False)
  assert proc.returncode != 0 and "has no runs" in proc.stderr


def test_final_training_judges_at_another_resolution_only_when_asked(tiny_run, tmp_path):
  # The run's views at 16 x 16 instead of the run's 24 x 24: refused unless --any_resolution,
  # and then recorded in the header so that rows of the two sizes are never mixed.
  out = tmp_path / "small.json"
  common = [f"--results={tiny_run}", "--steps=4", "--views=2", "--strategies=farthest",
            "--config.data.width=16", "--config.data.height=16", f"--out={out}"]
  proc = _final_training(*common, check=False)
  assert proc.returncode != 0 and "resolution [16, 16] (the run's [24, 24])" in proc.stderr
  _final_training(*common, "--any_resolution")
  record = json.loads(out.read_text())
  assert record["header"]["judge_resolution"] == [16, 16]
  assert len(record["rows"]) == 1 and 0 < record["rows"][0]["psnr"] < 100
  same_size = tmp_path / "same.json"
  _final_training(f"--results={tiny_run}", "--steps=4", "--views=2", "--strategies=farthest",
                  f"--out={same_size}")
  proc = _final_training(*common[:-1], "--any_resolution", f"--out={tmp_path / 'x.json'}",
                         f"--reuse_rows_from={same_size}", check=False)
  assert proc.returncode != 0 and "another judge_resolution" in proc.stderr
  proc = _final_training(*common[:-1], "--any_resolution", "--reuse_run",
                         f"--out={tmp_path / 'y.json'}", check=False)
  assert proc.returncode != 0 and "--reuse_run" in proc.stderr
