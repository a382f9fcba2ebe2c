"""Hostile inputs to mfsample.planning: poses, view optimisation, configs, resumed runs.

For each entry point, a table of bad inputs and what they give: each row is a bad input and
its expected outcome, a clear error whose message names the field or the file, or a defined
behaviour (docs/reliability.md lists the same tables).
Kill-and-resume tests compare against an uninterrupted run of the tiny planning config.
"""

import json
import os
import shutil

import jax.numpy as jnp
import numpy as np
import pytest
from hostile_testlib import NAN, _cams, _set, _tree_files
from planning_testlib import random_model

from configs import camera_planning
from mfsample.config_checks import ConfigError
from mfsample.planning import optimize as view_optimize
from mfsample.planning import poses, runner, tables
from mfsample.planning.config import validate as validate_planning
from mfsample.selection import top_k
from mfsample.workdir import WorkdirError
from mfsample.your_data import sphere_candidates

# ====================================================================== poses, view optimisation


@pytest.mark.parametrize("call, message", [
    (lambda: poses.SphereSpec(radius=NAN), "SphereSpec.radius must be a finite number > 0.0"),
    (lambda: poses.SphereSpec(center=(0.0, 0.0)), "SphereSpec.center must be 3 numbers"),
    (lambda: poses.SphereSpec(fov_x=40.0), r"SphereSpec.fov_x must be a finite number in "
                                           r"\(0.0, 3.14"),
    (lambda: poses.SphereSpec(width=0), "SphereSpec.width must be an integer >= 1"),
    (lambda: poses.spherical_camera(jnp.zeros(3), poses.SphereSpec()),
     r"uv must have shape \[\.\.\., 2\], got \[3\]"),
    (lambda: poses.perturb_camera(_cams(1)[0], jnp.zeros(5)),
     r"xi must have shape \[6\] \(one tangent vector per camera\), got \[5\]"),
    (lambda: poses.perturb_camera(_cams(2), jnp.zeros(6)), r"xi must have shape \[2, 6\]"),
    (lambda: poses.se3_exp(jnp.zeros((2, 5))), r"xi must have shape \[\.\.\., 6\]"),
    (lambda: poses.camera_to_uv(_cams(2), center=(0.0, NAN, 0.0)), r"center\[1\] is not finite"),
    (lambda: view_optimize.OptimizeSettings(steps=2.5), "OptimizeSettings.steps must be an "
                                                        "integer >= 1, got 2.5"),
    (lambda: view_optimize.OptimizeSettings(lr=NAN), "OptimizeSettings.lr must be a finite"),
    (lambda: view_optimize.OptimizeSettings(resample_z="yes"), "resample_z must be True or False"),
    (lambda: view_optimize.optimize_spherical(random_model("lowrank", num=8), [NAN, 0.3],
                                              np.zeros((2, 2), np.float32),
                                              sphere=poses.SphereSpec()),
     r"uv0\[0\] is not finite"),
    (lambda: view_optimize.optimize_se3(random_model("lowrank", num=8), _cams(2),
                                        np.zeros((2, 2), np.float32)),
     "camera0 must be one unbatched"),
    (lambda: view_optimize.optimize_se3(random_model("lowrank", num=8), _cams(1)[0],
                                        np.full((2, 2), NAN, np.float32)),
     r"z\[0\] \(sample 0\) is not finite"),
    (lambda: top_k([0.3, 0.1], -1), "k must be an integer >= 0, got -1"),
    (lambda: top_k([0.3, NAN, 0.2], 1), r"values\[1\] is NaN \(1 of 3\)"),
    (lambda: top_k(np.zeros((2, 2)), 1), r"values must have shape \[B\], got \[2, 2\]"),
    (lambda: sphere_candidates(_cams(2), (0.0, 0.0, NAN), 4), r"center\[2\] is not finite"),
    (lambda: sphere_candidates(_cams(2), (0.0, 0.0, 0.0), 0), "num must be an integer >= 1"),
])
def test_planning_and_next_view_argument_table(call, message):
  with pytest.raises(ValueError, match=message):
    call()


# ====================================================================== planning configs

PLANNING_BAD = [  # (field, value, message fragment)
    ("seeds", (0, 1, 0), r"config.seeds = \(0, 1, 0\): repeats 0; each must appear once"),
    ("seeds", (), "must hold at least 1 item"),
    ("seeds", (-1,), "-1 is not an integer >= 0"),
    ("strategies", ("random", "random"), "repeats 'random'"),
    ("strategies", ("random", "best"), "'best' is not one of"),
    ("eval_views", (2, 5), r"config.eval_views = \(2, 5\): every count must be <= "
                           "config.max_views = 3"),
    ("eval_views", (2, 2), "repeats 2"),
    ("eval_views", (0, 3), "0 is not an integer >= 1"),
    ("max_views", 9, "config.max_views = 9 must be <= config.data.num_train = 8"),
    ("initial_view", 8, "config.initial_view = 8 must be < config.data.num_train = 8"),
    ("paired_references", ("farthest", "nope"), "'nope' is not one of"),
    ("data.kind", "nerf", "config.data.kind = 'nerf'"),
    ("data.num_train", 0, "config.data.num_train = 0"),
    ("data.synthetic.v_range", (0.6, 0.1), "strictly increasing"),
    ("data.synthetic.distance", 0.4, r"config.data.synthetic.distance = 0.4: must be a finite "
                                     r"number > 0.5"),
    ("rounds.steps", 0, "config.rounds.steps = 0"),
    ("rounds.warm_start", None, "config.rounds.warm_start = None: must be True or False"),
    ("round_train.train.log_every", 0, "config.round_train.train.log_every = 0"),
    ("final_train.train.num_steps", -5, "config.final_train.train.num_steps = -5"),
    ("final_train.sampler.rank", 0, "config.final_train.sampler.rank = 0"),
    ("strategy.ours.select_samples", 1, "config.strategy.ours.select_samples = 1: must be an "
                                        "integer >= 2"),
    ("strategy.optimize.samples", 1, "config.strategy.optimize.samples = 1"),
    ("strategy.optimize.sampler", "gauss", "config.strategy.optimize.sampler = 'gauss'"),
    ("strategy.fisher.groups", ("means", "means"), "'means' repeats"),
    ("strategy.activenerf.prior_var", 0.0, "config.strategy.activenerf.prior_var = 0.0"),
    ("strategy.acp.resolution", 0, "config.strategy.acp.resolution = 0"),
    ("figures.landscape_u", 0, "config.figures.landscape_u = 0"),
]


@pytest.mark.parametrize("field, value, message", PLANNING_BAD)
def test_planning_config_table(field, value, message):
  config = camera_planning.get_config("tiny")
  _set(config, field, value)
  with pytest.raises(ConfigError, match=message):
    validate_planning(config)


def test_warm_start_with_densifying_rounds_is_refused_on_entry():
  config = camera_planning.get_config("tiny")
  config.rounds.warm_start = True
  config.round_train.densify.start = 50
  with pytest.raises(ConfigError, match="cannot densify: config.round_train.densify.start"):
    validate_planning(config)


def test_run_camera_planning_writes_nothing_for_a_bad_config(tmp_path):
  config = camera_planning.get_config("tiny")
  config.seeds = (0, 0)
  with pytest.raises(ConfigError, match="repeats 0"):
    runner.run_camera_planning(config, str(tmp_path / "run"))
  assert not (tmp_path / "run").exists()


def _record(strategy, seed, psnr):
  return {"strategy": strategy, "label": strategy, "seed": seed, "seconds": 1.0,
          "round_seconds": [0.0, 1.0], "optimisation": [],
          "metrics": {"3": {"psnr": psnr, "ssim": 0.5, "lpips": None}}}


def test_tables_count_a_repeated_run_once():
  records = [_record("random", 0, 20.0), _record("random", 1, 22.0), _record("random", 0, 20.0),
             _record("farthest", 0, 21.0), _record("farthest", 1, 21.0)]
  summary = tables.summarise(records, (3,))
  assert summary["random"]["3"]["psnr"]["values"] == [20.0, 22.0]
  assert tables.seconds_summary(records)["random"]["runs"] == 2
  paired = tables.paired_differences(records, (3,), "farthest")
  assert paired["random"]["3"]["seeds"] == [0, 1]
  with pytest.raises(ValueError, match="two different records of strategy 'random', seed 0"):
    tables.summarise(records + [_record("random", 0, 25.0)], (3,))


# ====================================================================== planning resume


def _planning_config():
  config = camera_planning.get_config("tiny")
  config.strategies = ("random", "farthest")
  config.figures.enabled = False
  return config


def _comparable(results):
  """results.json less wall-clock, as JSON text."""
  drop = {"seconds", "round_seconds", "seconds_this_call", "run_seconds"}

  def strip(x):
    if isinstance(x, dict):
      return {k: strip(v) for k, v in x.items() if k not in drop}
    if isinstance(x, (list, tuple)):
      return [strip(v) for v in x]
    return x

  return json.dumps(strip(results), sort_keys=True)


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
  """An uninterrupted tiny planning run (two strategies, one seed) and its workdir."""
  workdir = tmp_path_factory.mktemp("planned")
  return runner.run_camera_planning(_planning_config(), str(workdir)), workdir


@pytest.mark.slow
def test_planning_killed_during_a_run_resumes_to_the_same_results(planned, tmp_path,
                                                                  monkeypatch):
  reference, _ = planned
  plan_views, calls = runner.plan_views, []

  def killed_in_second_run(*args, **kwargs):
    calls.append(args[0].name)
    if len(calls) == 2:
      raise KeyboardInterrupt("killed")
    return plan_views(*args, **kwargs)

  monkeypatch.setattr(runner, "plan_views", killed_in_second_run)
  with pytest.raises(KeyboardInterrupt):
    runner.run_camera_planning(_planning_config(), str(tmp_path))
  assert sorted(os.listdir(tmp_path / "runs")) == ["random-seed0.json"]
  assert not (tmp_path / "results.json").exists()
  monkeypatch.setattr(runner, "plan_views", plan_views)
  resumed = runner.run_camera_planning(_planning_config(), str(tmp_path))
  assert _comparable(resumed) == _comparable(reference)


@pytest.mark.slow
def test_planning_killed_between_its_result_files_resumes(planned, tmp_path, monkeypatch):
  """Runs written, results.json / table.md not (or killed while being replaced)."""
  reference, workdir = planned
  shutil.copytree(workdir, tmp_path / "run")
  (tmp_path / "run" / "results.json").unlink()
  (tmp_path / "run" / "table.md").write_text("an older table")
  replace = os.replace

  def dies_on_table(src, dst):
    if dst.endswith("table.md"):
      raise KeyboardInterrupt("killed")
    return replace(src, dst)

  monkeypatch.setattr(os, "replace", dies_on_table)
  with pytest.raises(KeyboardInterrupt):
    runner.run_camera_planning(_planning_config(), str(tmp_path / "run"))
  monkeypatch.setattr(os, "replace", replace)
  assert (tmp_path / "run" / "table.md").read_text() == "an older table"  # never truncated
  assert not [n for n in os.listdir(tmp_path / "run") if ".tmp" in n]
  resumed = runner.run_camera_planning(_planning_config(), str(tmp_path / "run"))
  assert _comparable(resumed) == _comparable(reference)
  assert (tmp_path / "run" / "table.md").read_text() == (workdir / "table.md").read_text()


@pytest.mark.slow
def test_a_damaged_run_record_is_reported_and_computed_again(planned, tmp_path):
  reference, workdir = planned
  shutil.copytree(workdir, tmp_path / "run")
  record = tmp_path / "run" / "runs" / "farthest-seed0.json"
  record.write_text(record.read_text()[:100])  # truncated by a crash of another tool
  with pytest.warns(UserWarning, match=r"farthest-seed0\.json is damaged"):
    resumed = runner.run_camera_planning(_planning_config(), str(tmp_path / "run"))
  assert _comparable(resumed) == _comparable(reference)
  assert json.loads(record.read_text())["strategy"] == "farthest"


def test_planning_refuses_a_workdir_of_another_protocol(planned, tmp_path):
  _, workdir = planned
  shutil.copytree(workdir, tmp_path / "run")
  before = _tree_files(tmp_path)
  config = _planning_config()
  config.final_train.train.num_steps = 13
  with pytest.raises(WorkdirError, match=r"differences: final_train.train.num_steps\)"):
    runner.run_camera_planning(config, str(tmp_path / "run"))
  (tmp_path / "run" / "config.json").write_text("")  # unknown protocol: refused too
  before = _tree_files(tmp_path)
  with pytest.raises(WorkdirError, match="config.json is unreadable"):
    runner.run_camera_planning(_planning_config(), str(tmp_path / "run"))
  assert _tree_files(tmp_path) == before
