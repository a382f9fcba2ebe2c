"""Every config file and variant loads from the command line, overrides apply, typos fail."""

import os
import pathlib
import re
import subprocess
import sys
import textwrap

import pytest
from absl import flags
from ml_collections import config_flags

from configs import camera_planning, uncertainty_quality
from mfsample.planning import config as planning_config
from mfsample.planning import runner
from mfsample.planning.strategies import NAMES, make_strategy
from mfsample.quality.config import validate as validate_quality

ROOT = pathlib.Path(__file__).resolve().parents[2]


def _load(spec, *overrides):
  argv = ["prog", f"--config={ROOT / 'configs' / spec}", *overrides]
  fv = flags.FlagValues()
  config_flags.DEFINE_config_file("config", None, "", flag_values=fv, lock_config=True,
                                  sys_argv=argv)
  fv(argv)
  return fv.config


@pytest.mark.parametrize("variant", ["", "lego", "tiny"])
def test_training_variants_load_and_override(variant):
  config = _load(f"train.py:{variant}" if variant else "train.py", "--config.sampler.rank=4",
                 "--config.loss.volume_weight=1.0")
  assert config.sampler.rank == 4 and config.loss.volume_weight == 1.0
  assert config.data.kind == {"": "scene", "lego": "blender", "tiny": "synthetic"}[variant]
  with pytest.raises(AttributeError):
    config.sampler.ranks = 3  # locked: typos are errors


@pytest.mark.parametrize("variant", ["", *planning_config.VARIANTS, "lego,rounds2000,fullres"])
def test_planning_variants_load_and_name_real_strategies(variant):
  config = _load(f"camera_planning.py:{variant}", '--config.seeds=(3,4)')
  assert config.seeds == (3, 4)
  assert set(config.strategies) <= set(NAMES) and set(config.paired_references) <= set(NAMES)
  assert max(config.eval_views) <= config.max_views
  # The rounds' training length is one field, whatever the variant.
  assert config.round_train.train.num_steps == config.rounds.steps
  assert runner.round_recipe(config, "lowrank").settings.num_steps == config.rounds.steps


def test_unknown_variants_are_refused_by_name():
  with pytest.raises(ValueError, match="unknown variant 'legoo'.*known: lego"):
    camera_planning.get_config("legoo")
  from configs import train
  with pytest.raises(ValueError, match="unknown variant 'big'"):
    train.get_config("big")


def test_variants_combine_in_order():
  config = camera_planning.get_config("lego,rounds2000")
  assert config.data.kind == "blender" and config.rounds.steps == 2000
  assert "ours_opt_sel" not in config.strategies  # lego has no oracle for new poses


@pytest.mark.parametrize("variant", ["", *uncertainty_quality.VARIANTS, "candidates,lego"])
def test_uncertainty_quality_variants_load_and_override(variant):
  config = _load(f"uncertainty_quality.py:{variant}", "--config.ause.seeds=(3,)",
                 "--config.candidates.samples=(2,)")
  assert config.ause.seeds == (3,) and config.candidates.samples == (2,)
  assert config.ause.enabled or config.candidates.enabled
  validate_quality(config)
  with pytest.raises(AttributeError):
    config.ause.sampler = ("lowrank:2",)  # locked: typos are errors


def test_ablation_overrides_change_the_round_model_of_ours_sel():
  # docs/uncertainty_quality.md runs the paper's Table 4 as override lines of the planning
  # config: Ours (Sel.) trains its round models with `round_train.sampler`.
  assert make_strategy("ours_sel").model_kind == "stochastic"
  for kind, rank in (("diagonal", 2), ("block", 2), ("lowrank", 10), ("deterministic", 2)):
    config = _load("camera_planning.py", "--config.strategies=('ours_sel',)",
                   f"--config.round_train.sampler.kind={kind}",
                   f"--config.round_train.sampler.rank={rank}")
    plan = runner.round_recipe(config, "stochastic")
    assert (plan.spec.kind, plan.spec.rank) == (kind, rank)
    assert plan.settings.num_steps == config.rounds.steps


def _documented_configs():
  """Every `--config=configs/...` of README.md and docs/*.md (file and variants)."""
  texts = [(ROOT / "README.md").read_text()] + [p.read_text() for p in
                                                 sorted((ROOT / "docs").glob("*.md"))]
  found = set()
  for text in texts:
    found.update(re.findall(r"--config=(configs/[\w.]+\.py(?::[\w,]+)?)", text))
  return sorted(found)


def test_documented_configs_load_without_pythonpath(tmp_path):
  """The commands of README and docs as a user types them: from the repository root with no
  PYTHONPATH, each config file (and variant) loads through absl as the mains load it. The
  loader is a script file outside the repository, so that, as for `python experiments/x.py`,
  the repository root is not on sys.path (`python -c` would put it there)."""
  specs = _documented_configs()
  assert len(specs) >= 10, specs  # the docs name a dozen; a broken regex finds none
  script = textwrap.dedent("""
      import sys
      from absl import flags
      from ml_collections import config_flags
      for i, spec in enumerate(sys.argv[1:]):
        fv = flags.FlagValues()
        argv = ["prog", "--config=" + spec]
        config_flags.DEFINE_config_file("config", None, "", flag_values=fv, sys_argv=argv)
        fv(argv)
        # absl defers a loading error to the config's first use: use it.
        assert "seed" in fv.config.to_json_best_effort() or fv.config.keys()
        print("loaded", spec)
  """)
  loader = tmp_path / "load_configs.py"
  loader.write_text(script)
  env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
  out = subprocess.run([sys.executable, str(loader), *specs], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=300)
  assert out.returncode == 0, out.stderr[-3000:]
  assert out.stdout.count("loaded") == len(specs)
