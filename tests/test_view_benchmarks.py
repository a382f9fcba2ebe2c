"""`benchmarks/view_value.py` and `benchmarks/view_optimisation.py` end to end on tiny
planning runs (subprocesses: absl flags).

The docs' "What is the next view worth?" and "Does gradient ascent on the camera raise U?"
figures come from these scripts. What they promise: view_value's value of a candidate is
the protocol's own final model on the view set plus that candidate (so the value of the
view the run took next is the run's metric at that count), the prefix strategy's pick is
recomputed as the view its run took, a second call trains nothing, and `--cases=` only
prints where the run looked; view_optimisation replays Ours (Opt. Sel.) on the run's own
round models, so with the config's setting it reaches the poses the run reached.
"""

import json

import numpy as np
import planning_testlib
import pytest
from planning_testlib import tiny_config


def _script(name, *args):
  return planning_testlib.run_benchmark(name, *args).stdout


def _view_value(*args):
  return _script("view_value", *args)


def _tiny_run(workdir, strategies):
  path = planning_testlib.tiny_run(workdir, strategies)
  return json.loads(path.read_text()), path


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
  """Two strategies that train no round model (cheap), one seed, the tiny protocol."""
  return _tiny_run(tmp_path_factory.mktemp("run"), ("random", "farthest"))


def test_view_value_matches_the_protocol_and_resumes(tiny_run, tmp_path):
  results, path = tiny_run
  out = tmp_path / "value.json"
  flags = [f"--results={path}", "--cases=0:1", "--prefix=farthest",
           "--strategies=farthest,acp", "--repeat_top=1", f"--out={out}"]
  printed = _view_value(*flags)
  assert "warning" not in printed  # farthest's pick here is the view its run took
  record = json.loads(out.read_text())
  farthest, = [r for r in results["runs"] if r["strategy"] == "farthest"]
  num_candidates = results["num_candidates"]
  first_round = [r for r in record["rows"] if r["train_seed"] == 0]
  # The set alone and every candidate it does not hold, once each.
  assert sorted(r["candidate"] for r in first_round if r["candidate"] is not None) == sorted(
      c for c in range(num_candidates) if c != farthest["indices"][0])
  case, = record["cases"]
  taken = farthest["indices"][1]
  assert case["taken_by_prefix_run"] == taken
  assert case["strategies"]["farthest"]["pick"] == taken
  # The value of the view the run took is the run's own final model at two views.
  value, = [r["psnr"] for r in first_round if r["candidate"] == taken]
  assert value == pytest.approx(farthest["metrics"]["2"]["psnr"], abs=1e-3)
  assert all(1 <= s["pick_rank"] <= num_candidates - 1 for s in case["strategies"].values())

  rows_before = record["rows"]
  _view_value(*flags)  # resumes: every row is in the file already
  assert json.loads(out.read_text())["rows"] == rows_before


def test_view_value_without_cases_only_prints(tiny_run, tmp_path):
  _, path = tiny_run
  out = tmp_path / "value.json"
  printed = _view_value(f"--results={path}", "--cases=", f"--out={out}")
  assert "farthest: median" in printed and "random: median" in printed
  assert not out.exists()


def test_view_optimisation_replays_the_run(tmp_path):
  results, path = _tiny_run(tmp_path / "run", ("ours_opt_sel",))
  config = tiny_config()
  own = f"2:{config.strategy.optimize.lr:g}"  # the config's M and learning rate
  assert config.strategy.optimize.samples == 2
  out = tmp_path / "opt.json"
  _script("view_optimisation", f"--results={path}", f"--settings={own}", f"--out={out}")
  rows = json.loads(out.read_text())["rows"]
  run, = results["runs"]
  assert [r["views"] for r in rows] == list(range(1, len(run["indices"])))
  for row in rows:
    info = run["optimisation"][row["views"]]
    travel = np.linalg.norm(np.subtract(info["uv"], info["uv0"]))
    replay, = row["variants"].values()
    assert replay["uv_travel"] == pytest.approx(travel, abs=1e-5)
    assert np.isfinite(replay["u_end"]) and 1 <= replay["rank_among_candidates"] <= 9
    assert all(np.isfinite(v) for probe in row["smoothness"].values() for v in probe.values())
