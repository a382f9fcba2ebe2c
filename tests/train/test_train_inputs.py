"""Hostile inputs to mfsample.train: configs, train_and_evaluate, checkpoints.

For each entry point, a table of bad inputs and what they give: each row is a bad input and
its expected outcome, a clear error whose message names the field or the file, or a defined
behaviour (docs/reliability.md lists the same tables).
Kill-and-resume and corrupt-file tests compare against uninterrupted runs. Tiny sizes
throughout: the compiled functions are those of tests/train/test_train.py, so a full suite
compiles them once.
"""

import json
import os
import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from absl import flags
from conftest import tiny_config, train_with
from hostile_testlib import NAN, _set, _tree_files
from ml_collections import config_flags
from test_train import resume_config

from mfsample import jobs
from mfsample.config_checks import ConfigError
from mfsample.train import checkpoint as ckpt
from mfsample.train import experiment
from mfsample.train.config import validate as validate_training
from mfsample.train.experiment import train_and_evaluate
from mfsample.workdir import WorkdirError

# ====================================================================== training configs

TRAINING_BAD = [  # (field, value, message fragment)
    ("seed", -1, r"config.seed = -1: must be an integer in \[0, 2147483647\]"),
    ("data.kind", "colmapp", "config.data.kind = 'colmapp': must be one of"),
    ("data.downscale", 0, "config.data.downscale = 0: must be an integer >= 1"),
    ("data.background", (1.0, 1.0), "config.data.background = .*: must be 3 finite numbers"),
    ("data.background", (1.0, NAN, 1.0), "must be 3 finite numbers in"),
    ("data.init_bounds", (1.3, -1.3), "strictly increasing"),
    ("data.extent", 0.0, "config.data.extent = 0.0: must be a finite number > 0.0"),
    ("data.synthetic.sh_degree", 4, r"must be an integer in \[0, 3\]"),
    ("model.sh_degree", 5, r"config.model.sh_degree = 5: must be an integer in \[0, 3\]"),
    ("model.init_points", 0, "config.model.init_points = 0: must be an integer >= 1"),
    ("model.init_opacity", 1.0, "config.model.init_opacity = 1.0: must be a finite number"),
    ("sampler.kind", "gauss", "config.sampler.kind = 'gauss'"),
    ("sampler.rank", 0, "config.sampler.rank = 0: must be an integer >= 1"),
    ("sampler.groups", ("means", "means"), "'means' repeats"),
    ("sampler.groups", ("means", "colour"), "'colour' is not one"),
    ("sampler.num_samples", 0, "config.sampler.num_samples = 0"),
    ("sampler.z", "halton", "config.sampler.z = 'halton'"),
    ("sampler.bounds.means", 0.0, "config.sampler.bounds.means = 0.0"),
    ("sampler.lr.quats", -1e-4, "config.sampler.lr.quats = -0.0001"),
    ("loss.ssim_weight", 1.5, r"config.loss.ssim_weight = 1.5: must be a finite number in \[0"),
    ("loss.volume_every", 0, "config.loss.volume_every = 0"),
    ("optim.position_lr_final", 0.0, "config.optim.position_lr_final = 0.0"),
    ("densify.every", 0, "config.densify.every = 0: must be an integer >= 1"),
    ("densify.opacity_reset_every", 0, "config.densify.opacity_reset_every = 0"),
    ("densify.min_opacity", 1.0, "config.densify.min_opacity = 1.0"),
    ("render.max_intersections", 0, "config.render.max_intersections = 0"),
    ("render.max_budget", 1024, "config.render.max_budget = 1024: must be an integer >= "
                                "max_intersections = 4096"),
    ("render.tile_size", 0, "config.render.tile_size = 0"),
    ("render.chunks_per_step", 0, "config.render.chunks_per_step = 0"),
    ("train.num_steps", 0, "config.train.num_steps = 0: must be an integer >= 1"),
    ("train.checkpoint_every", 0, "config.train.checkpoint_every = 0: must be an integer >= 1"),
    ("train.keep_checkpoints", -1, "config.train.keep_checkpoints = -1: must be an integer"),
    ("train.keep_checkpoints", 0, "config.train.keep_checkpoints = 0"),
    ("train.log_every", 0, "config.train.log_every = 0"),
    ("train.num_steps", None, "config.train.num_steps = None: must be an integer"),
    ("train.progress", None, "config.train.progress = None: must be True or False"),
    ("eval.lpips_net", "vgg", "config.eval.lpips_net = 'vgg'"),
    ("eval.uncertainty_samples", 1, "config.eval.uncertainty_samples = 1: must be 0"),
    ("eval.save_images", -1, "config.eval.save_images = -1"),
]


@pytest.mark.parametrize("field, value, message", TRAINING_BAD)
def test_training_config_table(field, value, message):
  config = tiny_config("lowrank")
  *parents, leaf = field.split(".")
  node = config
  for p in parents:
    node = node[p]
  with config.unlocked():
    node[leaf] = value
  with pytest.raises(ConfigError, match=message):
    validate_training(config)


@pytest.mark.parametrize("field, value", [("train.num_steps", 10.5), ("train.progress", "yes"),
                                          ("sampler.rank", "2")])
def test_config_dicts_refuse_another_type_on_assignment(field, value):
  config = tiny_config("lowrank")  # (and so does the command line: --config.train.num_steps)
  with pytest.raises(TypeError, match=f"Could not override field '{field.split('.')[-1]}'"):
    _set(config, field, value)


@pytest.mark.parametrize("override, error, message", [
    ("--config.train.nonexistent=3", AttributeError, "'nonexistent'"),
    ("--config.trian.num_steps=3", KeyError, "Did you mean \"train\" instead of \"trian\""),
])
def test_unknown_fields_on_the_command_line_are_refused_by_name(override, error, message):
  """ml_collections refuses a field the config lacks while absl parses the command line,
  before an experiment's main (and its validation) runs, naming the field; a close match is
  suggested."""
  config_file = os.path.join(os.path.dirname(__file__), "..", "..", "configs", "train.py")
  argv = ["prog", f"--config={config_file}:tiny", override]
  fv = flags.FlagValues()
  config_flags.DEFINE_config_file("config", None, "", flag_values=fv, lock_config=True,
                                  sys_argv=argv)
  with pytest.raises(error, match=message):
    fv(argv)


def test_train_refuses_a_bad_config_before_any_step(tiny_dataset, tmp_path):
  # Not a ZeroDivisionError after the first step, nor every checkpoint deleted as written.
  for field, value in (("checkpoint_every", 0), ("keep_checkpoints", -1)):
    config = tiny_config("lowrank", **{f"train.{field}": value})
    with pytest.raises(ConfigError, match=f"config.train.{field}"):
      validate_training(config)
    with pytest.raises(ValueError, match=f"{field} must be an integer >= 1"):
      train_with(tiny_config("lowrank"), tiny_dataset, checkpoint_dir=str(tmp_path / "c"),
                 **{field: value})
  assert not (tmp_path / "c").exists()
  for keep in (0, -1, True, 1.5):
    with pytest.raises(ValueError, match="keep = .*: must be an integer >= 1"):
      ckpt.save_checkpoint(str(tmp_path / "c"), {"a": jnp.zeros(2)}, {"step": 1}, keep=keep)


# ====================================================================== train_and_evaluate


def _write_workdir(workdir, config_text, checkpoint=True):
  os.makedirs(os.path.join(workdir, "checkpoints"), exist_ok=True)
  with open(os.path.join(workdir, "config.json"), "w") as f:
    f.write(config_text)
  if checkpoint:
    with open(os.path.join(workdir, "checkpoints", "ckpt_00000008.npz"), "wb") as f:
      f.write(b"stands for a checkpoint")


@pytest.mark.parametrize("case, error, message", [
    ("different config", WorkdirError,
     r"holds training results made with a different config \(differences: "
     r"loss.ssim_weight, sampler.rank\)"),
    ("empty config.json", WorkdirError, r"config.json is unreadable"),
    ("config.json not an object", WorkdirError, "does not hold a JSON object"),
    ("invalid config", ConfigError, "config.train.checkpoint_every = 0"),
    ("mistyped --config path", OSError, "Failed loading config file"),
    ("missing dataset", FileNotFoundError, "No NeRF Synthetic scene"),
])
def test_train_and_evaluate_writes_nothing_for_a_bad_call(tmp_path, case, error, message):
  """Each case leaves the workdir exactly as it was: config.json neither overwritten nor
  emptied, no results of two configs mixed."""
  workdir = str(tmp_path / "run")
  config = tiny_config("lowrank")
  stored = tiny_config("lowrank")
  stored.loss.ssim_weight = 0.5
  stored.sampler.rank = 3
  text = {"different config": stored.to_json_best_effort(indent=2),
          "empty config.json": "", "config.json not an object": "[1, 2]"}.get(
              case, config.to_json_best_effort(indent=2))
  _write_workdir(workdir, text)
  if case == "invalid config":
    config.train.checkpoint_every = 0
  elif case == "mistyped --config path":
    argv = ["prog", f"--config={tmp_path / 'configs' / 'trian.py'}"]
    fv = flags.FlagValues()
    config_flags.DEFINE_config_file("config", None, "", flag_values=fv, lock_config=True,
                                    sys_argv=argv)
    fv(argv)
    config = fv.config  # absl defers the error to the first use
  elif case == "missing dataset":
    config.data.kind = "blender"
    config.data.path = str(tmp_path / "nowhere")
    shutil.rmtree(workdir)
  before = _tree_files(tmp_path)
  with pytest.raises(error, match=message):
    train_and_evaluate(config, workdir)
  assert _tree_files(tmp_path) == before


def test_the_workdir_guard_lets_speed_and_bookkeeping_fields_differ(tmp_path):
  config = tiny_config("lowrank")
  _write_workdir(str(tmp_path), config.to_json_best_effort(indent=2))
  config.render.chunks_per_step = 64
  config.train.checkpoint_every = 7
  config.train.keep_checkpoints = 5
  config.train.progress = True
  jobs.check_workdir(experiment.JOB, config, str(tmp_path))  # the same results, written otherwise
  config.train.log_every = 3
  with pytest.raises(WorkdirError, match=r"differences: train.log_every\)"):
    jobs.check_workdir(experiment.JOB, config, str(tmp_path))
  # A config.json with nothing computed from it is simply replaced.
  os.remove(tmp_path / "checkpoints" / "ckpt_00000008.npz")
  jobs.check_workdir(experiment.JOB, config, str(tmp_path))


# ====================================================================== checkpoints


@pytest.fixture(scope="module")
def straight(tiny_dataset):
  """The uninterrupted 16-step run of `resume_config` (densification, budget growth)."""
  return train_with(resume_config(), tiny_dataset)


def _assert_same_run(a, b, stopped_at=None):
  """Equal states, and equal logs (`train(stop_at=n)` also logs step n, which a checkpoint
  written at n keeps)."""
  for x, y in zip(jax.tree.leaves(a.state), jax.tree.leaves(b.state), strict=True):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
  strip = lambda h: [{k: v for k, v in e.items() if k != "seconds"} for e in h]
  assert strip(a.history) == [e for e in strip(b.history) if e["step"] != stopped_at
                              or stopped_at in [f["step"] for f in a.history]]


@pytest.mark.slow
@pytest.mark.parametrize("kill_at", [5, 8, 13])
def test_training_killed_at_several_points_resumes_bit_identically(tiny_dataset, straight,
                                                                   tmp_path, kill_at):
  """Killed before the first checkpoint (5), right after one (8), after densification (13):
  the resumed run equals the uninterrupted one, log included."""
  config, d = resume_config(), str(tmp_path / "checkpoints")
  train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=8, stop_at=kill_at)
  saved = [os.path.basename(p) for p in ckpt.list_checkpoints(d)]
  assert saved == ([] if kill_at < 8 else ["ckpt_00000008.npz"])
  resumed = train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=8)
  _assert_same_run(straight, resumed, stopped_at=kill_at)


@pytest.mark.slow
def test_a_corrupt_latest_checkpoint_falls_back_to_the_newest_intact_one(tiny_dataset, straight,
                                                                          tmp_path):
  config, d = resume_config(), str(tmp_path / "checkpoints")
  train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=8)
  latest = ckpt.list_checkpoints(d)[-1]
  assert latest.endswith("ckpt_00000016.npz")
  with open(latest, "r+b") as f:  # truncated, as by a full disk or an interrupted copy
    f.truncate(os.path.getsize(latest) // 2)
  with pytest.warns(UserWarning, match=r"ckpt_00000016.npz is unreadable \(BadZipFile"):
    resumed = train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=8)
  _assert_same_run(straight, resumed)  # re-ran 8 -> 16 from the intact checkpoint
  assert ckpt.read_meta(latest)["step"] == 16  # and replaced the corrupt file


@pytest.mark.parametrize("damage, message", [
    (lambda p: open(p, "wb").write(b"garbage"), r"unreadable \(ValueError"),  # not a zip
    (lambda p: open(p, "r+b").truncate(100), "BadZipFile"),
    (lambda p: np.savez(p, a=np.zeros(2)), r"KeyError.*__meta__"),
    (lambda p: np.savez(p, __meta__=np.asarray("{not json")), "JSONDecodeError"),
    (lambda p: np.savez(p, __meta__=np.asarray(json.dumps({"no": "step"}))), "no valid metadata"),
])
def test_unreadable_checkpoints_are_named(tmp_path, damage, message):
  path = ckpt.save_checkpoint(str(tmp_path), {"a": jnp.zeros(2)}, {"step": 3})
  damage(path)
  with pytest.raises(ckpt.CorruptCheckpointError, match=rf"ckpt_00000003.npz.*{message}"):
    ckpt.read_meta(path)


def test_without_an_intact_checkpoint_resuming_is_refused(tiny_dataset, tmp_path):
  config, d = resume_config(), tmp_path / "checkpoints"
  d.mkdir()
  for step in (8, 16):
    (d / f"ckpt_{step:08d}.npz").write_bytes(b"")
  with pytest.warns(UserWarning), pytest.raises(
      ckpt.CorruptCheckpointError, match=r"no readable checkpoint.*ckpt_00000016.*ckpt_00000008"):
    train_with(config, tiny_dataset, checkpoint_dir=str(d))


def test_checkpoints_of_another_config_are_refused(tiny_dataset, tmp_path):
  config, d = resume_config(), str(tmp_path / "checkpoints")
  train_with(config, tiny_dataset, checkpoint_dir=d, checkpoint_every=1, stop_at=1)
  other = resume_config()
  other.loss.ssim_weight = 0.5
  with pytest.raises(WorkdirError, match=r"different training settings \(differences: "
                                         r"loss.ssim_weight\)"):
    train_with(other, tiny_dataset, checkpoint_dir=d)
  other = resume_config()
  other.seed = 1
  with pytest.raises(WorkdirError, match="seed 0, this run has seed 1"):
    train_with(other, tiny_dataset, checkpoint_dir=d)
  other = resume_config()
  other.sampler.rank = 3
  with pytest.raises(WorkdirError, match="another sampler"):
    train_with(other, tiny_dataset, checkpoint_dir=d)


@pytest.mark.slow
def test_training_killed_between_its_result_files_resumes(tiny_dataset, straight, tmp_path,
                                                          monkeypatch):
  """Killed after the last checkpoint but before metrics.json: the rerun trains nothing and
  equals the uninterrupted run. Killed while metrics.json is being replaced: the previous
  file stays whole and no temporary is left."""
  from mfsample.train import evaluate as eval_lib

  config, workdir = resume_config(), str(tmp_path / "run")
  config.eval.uncertainty_samples = 0  # (test_train covers the maps: fewer compilations here)
  config.eval.save_images = 1
  evaluate = eval_lib.evaluate

  def killed(*args, **kwargs):
    raise KeyboardInterrupt("killed")

  monkeypatch.setattr(eval_lib, "evaluate", killed)
  with pytest.raises(KeyboardInterrupt):
    train_and_evaluate(config, workdir)
  assert os.path.exists(os.path.join(workdir, "train_log.json"))
  assert not os.path.exists(os.path.join(workdir, "metrics.json"))
  monkeypatch.setattr(eval_lib, "evaluate", evaluate)
  resumed = train_and_evaluate(config, workdir)
  for x, y in zip(jax.tree.leaves(straight.state), jax.tree.leaves(resumed), strict=True):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
  metrics_path = os.path.join(workdir, "metrics.json")
  metrics = open(metrics_path).read()
  assert json.loads(metrics)["steps"] == 16

  replace = os.replace

  def dies_on_metrics(src, dst):
    if str(dst).endswith("metrics.json"):
      raise KeyboardInterrupt("killed")
    return replace(src, dst)

  monkeypatch.setattr(os, "replace", dies_on_metrics)
  with pytest.raises(KeyboardInterrupt):
    train_and_evaluate(config, workdir)
  assert open(metrics_path).read() == metrics  # the previous file, whole
  assert not [n for n in os.listdir(workdir) if ".tmp" in n]


def test_a_checkpoint_of_the_same_sampler_resumes_whatever_rounding_its_extent_had():
  """The means' bound comes from the scene extent: a checkpoint whose record gives it a few
  float32 roundings apart (another process, version or XLA setting) is the same run; a
  bound or a kind that differs is another run."""
  from mfsample.train.loop import _same_record

  spec = {"kind": "lowrank", "rank": 2, "bounds": [["means", 3.365836125401988],
                                                   ["sh_dc", 0.5]], "z": "sobol"}
  rounded = {**spec, "bounds": [["means", 3.365836187111537], ["sh_dc", 0.5]]}
  assert _same_record(rounded, spec)
  assert not _same_record({**spec, "bounds": [["means", 3.4], ["sh_dc", 0.5]]}, spec)
  assert not _same_record({**spec, "rank": 3}, spec)
  assert not _same_record({**spec, "z": "uniform"}, spec)
  assert not _same_record({**spec, "bounds": [["means", 3.365836125401988]]}, spec)


def test_the_scene_extent_is_computed_from_the_stored_poses_in_float64(monkeypatch):
  """Not from `Camera.center` (float32, by XLA, rounded differently per device and XLA
  setting): every process of a run gets the same extent, bit for bit."""
  from mfsample import orbit_camera
  from mfsample.camera import Camera
  from mfsample.data.datasets import scene_extent

  cams = [orbit_camera(a, 0.3, width=8, height=8, distance=3.0) for a in (0.0, 1.0, 2.0)]
  batch = jax.tree.map(lambda *x: np.stack(x), *cams)
  w2c = np.asarray(batch.world_to_camera, np.float64)
  centres = -np.einsum("vji,vj->vi", w2c[:, :3, :3], w2c[:, :3, 3])
  want = 1.1 * np.max(np.linalg.norm(centres - centres.mean(0), axis=-1))
  assert want > 0
  monkeypatch.setattr(Camera, "center", property(lambda self: 1 / 0))
  assert scene_extent(batch) == want
