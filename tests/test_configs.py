"""The configs load, every training field is documented, command-line overrides work, and
the planning configs that share a workdir differ only where the runner allows."""

import importlib
import json
import pathlib
import re

import pytest
from absl import flags
from ml_collections import config_flags

from mfsample.planning import runner, workdirs
from mfsample.planning.strategies import NAMES

CONFIGS = ["configs/train_default.py", "configs/train_lego.py", "configs/train_synthetic.py"]
ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("path", CONFIGS)
def test_config_loads_and_overrides(path):
  argv = ["prog", f"--config={ROOT / path}", "--config.sampler.rank=4",
          "--config.sampler.stochastic_until=3000", "--config.loss.volume_weight=1.0"]
  fv = flags.FlagValues()
  config_flags.DEFINE_config_file("config", None, "", flag_values=fv, lock_config=True,
                                  sys_argv=argv)
  fv(argv)
  config = fv.config
  assert config.sampler.rank == 4 and config.sampler.stochastic_until == 3000
  assert config.loss.volume_weight == 1.0
  with pytest.raises(AttributeError):
    config.sampler.ranks = 3  # locked: typos are errors
  assert config.data.kind in ("synthetic", "blender", "scene")


def test_every_default_field_has_a_comment():
  """Each field assignment carries a comment on its line or on the line above."""
  lines = (ROOT / "configs/train_default.py").read_text().splitlines()
  for i, line in enumerate(lines):
    if re.match(r"\s+\w+(\.\w+)+ = ", line):
      assert "#" in line or lines[i - 1].strip().startswith("#"), line


PLANNING_CONFIGS = sorted(p.name for p in (ROOT / "configs").glob("camera_planning*.py"))
# Configs the README or docs/camera_planning.md run in the workdir of another: they may
# differ only in the fields that `workdirs` lets change between calls (seeds, strategies,
# presentation).
SHARED_WORKDIRS = {"camera_planning_results.py": "camera_planning.py",
                   "camera_planning_seeds8.py": "camera_planning.py",
                   "camera_planning_lego_seeds8.py": "camera_planning_lego.py",
                   "camera_planning_lego_rounds2000_seeds16.py":
                       "camera_planning_lego_rounds2000.py",
                   "camera_planning_rounds2000_seeds16.py": "camera_planning_rounds2000.py",
                   "camera_planning_rounds2000_best.py": "camera_planning_rounds2000.py",
                   "camera_planning_rounds2000_fresh.py": "camera_planning_rounds2000.py",
                   "camera_planning_rounds2000_seeds24.py": "camera_planning_rounds2000.py"}


def _planning_config(name):
  return importlib.import_module(f"configs.{name[:-3]}").get_config()


@pytest.mark.parametrize("name", PLANNING_CONFIGS)
def test_planning_config_names_real_strategies(name):
  config = _planning_config(name)
  assert set(config.strategies) <= set(NAMES)
  assert set(config.paired_references) <= set(NAMES)
  assert max(config.eval_views) <= config.max_views and len(config.seeds) >= 1


@pytest.mark.parametrize("name", PLANNING_CONFIGS)
def test_round_training_length_is_one_field(name):
  """config.json records the rounds' training length the runner uses (`round_config`)."""
  config = _planning_config(name)
  assert config.round_train.train.num_steps == config.rounds.steps
  config.rounds.steps += 7
  assert config.round_train.train.num_steps == config.rounds.steps
  if not config.rounds.warm_start:
    assert runner.round_config(config, "lowrank").train.num_steps == config.rounds.steps


def _comparable(name):
  return workdirs.comparable_config(json.loads(_planning_config(name).to_json_best_effort()))


@pytest.mark.parametrize("name,base", sorted(SHARED_WORKDIRS.items()))
def test_configs_sharing_a_workdir_differ_only_in_resumable_fields(name, base):
  assert _comparable(name) == _comparable(base)


def test_a_different_protocol_needs_its_own_workdir():
  assert _comparable("camera_planning_scale.py") != _comparable("camera_planning.py")


# Committed planning results and the config the documentation names for each: rerunning
# its command must redo the same protocol (the resume guard would refuse otherwise).
COMMITTED_RESULTS = {"camera_planning_default": "camera_planning_results.py",
                     "camera_planning_seeds8": "camera_planning_seeds8.py",
                     "camera_planning_lego": "camera_planning_lego.py",
                     "camera_planning_lego_seeds8": "camera_planning_lego_seeds8.py",
                     "camera_planning_lego_rounds2000": "camera_planning_lego_rounds2000.py",
                     "camera_planning_lego_rounds2000_seeds16":
                         "camera_planning_lego_rounds2000_seeds16.py",
                     "camera_planning_lego_rounds2000_fisher":
                         "camera_planning_lego_rounds2000_fisher.py",
                     "camera_planning_lego_rounds2000_authors":
                         "camera_planning_lego_rounds2000_authors.py",
                     "camera_planning_lego_rounds2000_fullres":
                         "camera_planning_lego_rounds2000_fullres.py",
                     "camera_planning_scale": "camera_planning_scale.py",
                     "camera_planning_rounds2000": "camera_planning_rounds2000.py",
                     "camera_planning_rounds2000_seeds16":
                         "camera_planning_rounds2000_seeds16.py",
                     "camera_planning_rounds2000_best": "camera_planning_rounds2000_best.py",
                     "camera_planning_rounds2000_fresh": "camera_planning_rounds2000_fresh.py",
                     "camera_planning_rounds2000_seeds24":
                         "camera_planning_rounds2000_seeds24.py",
                     "camera_planning_rounds2000_opt_sel_seeds24":
                         "camera_planning_rounds2000_opt_sel_seeds24.py"}


@pytest.mark.parametrize("results,name", sorted(COMMITTED_RESULTS.items()))
def test_committed_results_were_made_with_their_config(results, name):
  recorded = json.loads((ROOT / "results" / results / "config.json").read_text())
  assert workdirs.differences(workdirs.comparable_config(recorded), _comparable(name)) == []


# Farthest point trains no round model, so the round length cannot change its views or
# its final models: docs/camera_planning.md pairs the 2000-step runs with it on that ground.
@pytest.mark.parametrize("short,long", [("camera_planning_seeds8", "camera_planning_rounds2000"),
                                        ("camera_planning_lego_seeds8",
                                         "camera_planning_lego_rounds2000")])
def test_farthest_point_runs_do_not_depend_on_the_round_length(short, long):
  def farthest(name):
    results = json.loads((ROOT / "results" / name / "results.json").read_text())
    return results["round_steps"], {r["seed"]: r for r in results["runs"]
                                    if r["strategy"] == "farthest"}
  (short_steps, short_runs), (long_steps, long_runs) = farthest(short), farthest(long)
  assert short_steps < long_steps and set(short_runs) == set(long_runs)
  for seed, run in short_runs.items():
    assert run["indices"] == long_runs[seed]["indices"], seed
    assert run["metrics"] == long_runs[seed]["metrics"], seed
