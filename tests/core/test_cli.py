"""The `mfsample` command: every job and the viewer, configs from the package, and a wheel
that runs a job in a fresh environment outside the repository."""

import importlib
import json
import os
import pathlib
import re
import shlex
import shutil
import subprocess
import sys

import numpy as np
import pytest
from absl import flags
from ml_collections import config_flags

from mfsample import cli

ROOT = pathlib.Path(__file__).resolve().parents[2]
JOB_COMMANDS = [name for name, c in cli.COMMANDS.items() if c.config]


def _load(argv):
  """The config that `mfsample.jobs.main` parses from `argv` (absl and config_flags)."""
  fv = flags.FlagValues()
  config_flags.DEFINE_config_file("config", None, "", flag_values=fv, lock_config=True,
                                  sys_argv=argv)
  flags.DEFINE_string("workdir", None, "", flag_values=fv)
  fv(argv)
  return fv.config


def _first_int_field(config, prefix=""):
  """The dotted name of the first integer field of a ConfigDict (depth first)."""
  for key, value in config.items():
    if type(value) is int:
      return prefix + key
    if hasattr(value, "items"):
      found = _first_int_field(value, f"{prefix}{key}.")
      if found:
        return found
  return None


def test_every_script_of_experiments_is_a_command():
  scripts = {p.stem.replace("_", "-") for p in (ROOT / "experiments").glob("*.py")}
  assert scripts == set(cli.COMMANDS)
  tomllib = pytest.importorskip("tomllib")  # Python 3.11
  scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
  assert scripts == {"mfsample": "mfsample.cli:main"}


@pytest.mark.parametrize("name", JOB_COMMANDS)
def test_every_variant_loads_from_the_package_as_from_the_clone(name):
  command = cli.COMMANDS[name]
  module = cli.config_module(command)
  path = pathlib.Path(cli.config_file(command))
  assert path.parent == ROOT / "mfsample" / "configs" and path.stem == command.config
  # The clone's configs/ file is the packaged one.
  clone = importlib.import_module(f"configs.{command.config}")
  assert clone.get_config is module.get_config and clone.VARIANTS is module.VARIANTS
  field = _first_int_field(module.get_config())  # an override on the command line
  for variant in ["", *module.VARIANTS]:
    args = [f"--config={variant}"] if variant else []
    config = _load(cli.job_argv(name, [*args, "--workdir=w", f"--config.{field}=7"]))
    expected = module.get_config(variant)
    *parents, leaf = field.split(".")
    node = expected
    for key in parents:
      node = node[key]
    node[leaf] = 7
    assert config.to_dict() == expected.to_dict(), (name, variant)
    with pytest.raises(AttributeError):
      config.seeed = 1  # locked, as the clone's scripts lock it


def test_config_values_resolve_to_the_packaged_file_or_stay_a_path():
  train = cli.config_file(cli.COMMANDS["train"])
  assert cli.job_argv("train", ["--config=tiny", "--workdir=w"]) == [
      "mfsample train", f"--config={train}:tiny", "--workdir=w"]
  assert cli.job_argv("train", ["--config", "lego,tiny"]) == [
      "mfsample train", "--config", f"{train}:lego,tiny"]
  # Absent: the default config, before any override (absl refuses overrides before it).
  assert cli.job_argv("train", ["--config.seed=3", "--workdir=w"]) == [
      "mfsample train", f"--config={train}", "--config.seed=3", "--workdir=w"]
  for spec in ("configs/train.py:tiny", "my_config.py", "/abs/c.py:lego,tiny"):
    assert cli.job_argv("train", [f"--config={spec}"])[1] == f"--config={spec}"
  config = _load(cli.job_argv("camera-planning", [
      f"--config={ROOT / 'configs' / 'camera_planning.py'}:lego,rounds2000"]))
  assert config.data.kind == "blender" and config.rounds.steps == 2000


def test_unknown_commands_and_variants_are_one_line(capsys):
  for argv, message in (
      (["trian"], r"^mfsample: unknown command 'trian'; commands: train, camera-planning, "),
      (["camera-planning", "--config=lego,legoo", "--workdir=w"],
       r"^mfsample camera-planning: --config: unknown variant 'legoo'; known: lego, "
       r"rounds2000, .*tiny")):
    with pytest.raises(SystemExit) as exit_:
      cli.main(["mfsample", *argv])
    assert exit_.value.code == 2  # as a job's config, data and workdir errors
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("\n") == 1 and re.match(message, out.err), out


def test_help_lists_the_commands_and_each_job_its_variants(capsys):
  cli.main(["mfsample"])
  listing = capsys.readouterr().out
  for name in cli.COMMANDS:
    assert f"\n  {name} " in listing
  for name in cli.COMMANDS:
    cli.main(["mfsample", name, "--help"])
    text = capsys.readouterr().out
    assert f"mfsample {name} " in text
    assert "--workdir" in text or name == "render-ply"  # the one command without a workdir
    if cli.COMMANDS[name].config:
      for variant in cli.config_module(cli.COMMANDS[name]).VARIANTS:
        assert f"\n  {variant} " in text, (name, variant)


def _documented_commands():
  """(page, command name, arguments) of every `mfsample COMMAND ...` in a bash block or an
  inline code span of README.md and docs/*.md."""
  found = []
  for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
    text = page.read_text()
    code = [block.replace("\\\n", " ") for block in
            re.findall(r"```bash\n(.*?)```", text, flags=re.S)]
    code += re.findall(r"(?<!`)`([^`\n]+)`(?!`)", text)
    for snippet in code:
      for line in snippet.splitlines():
        for match in re.finditer(r"(?:^|[\s;&|(])mfsample ([a-z][\w-]*)((?: +[^\s#]+)*)", line):
          found.append((page.name, match.group(1), shlex.split(match.group(2))))
  return found


def test_documented_commands_name_commands_variants_and_fields_that_exist():
  documented = _documented_commands()
  assert {name for _, name, _ in documented} >= {"train", "camera-planning", "viewer"}
  for page, name, args in documented:
    assert name in cli.COMMANDS, (page, name)
    if not cli.COMMANDS[name].config:
      continue
    args = [a for a in args if a.startswith(("--config", "--workdir"))]
    config = _load(cli.job_argv(name, args))  # variants, files and overrides as typed
    assert config is not None, (page, name, args)


def _run(cmd, **kwargs):
  out = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600,
                       check=False, **kwargs)
  assert out.returncode == 0, f"{cmd}\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
  return out


@pytest.mark.slow
def test_a_built_wheel_runs_a_job_in_a_fresh_environment(tmp_path):
  """The wheel of a copy of the sources, built offline by the installed setuptools, installed
  in a new virtual environment whose dependencies are this environment's packages; its
  `mfsample` command runs the tiny training job from a folder outside the repository."""
  source = tmp_path / "source"
  source.mkdir()
  for name in ("pyproject.toml", "README.md", "LICENSE"):
    shutil.copy(ROOT / name, source / name)
  shutil.copytree(ROOT / "mfsample", source / "mfsample",
                  ignore=shutil.ignore_patterns("__pycache__"))
  _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
        "--no-index", "--wheel-dir", tmp_path / "dist", source])
  (wheel,) = (tmp_path / "dist").glob("mfsample-*.whl")

  venv = tmp_path / "venv"
  _run([sys.executable, "-m", "venv", venv])
  python, script = venv / "bin" / "python", venv / "bin" / "mfsample"
  site = _run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"])
  # The dependencies: this environment's site-packages after the new one's (a venv's
  # --system-site-packages would reach the base interpreter's, not this environment's).
  import site as this_site

  (pathlib.Path(site.stdout.strip()) / "dependencies.pth").write_text(
      "\n".join(this_site.getsitepackages()) + "\n")
  _run([python, "-m", "pip", "install", "--no-deps", "--no-index", "--quiet", wheel])

  run = tmp_path / "elsewhere"
  run.mkdir()
  env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
  where = _run([python, "-c", "import mfsample, mfsample.cli as c; print(mfsample.__version__); "
                "print(mfsample.__file__); "
                "[print(c.config_file(x)) for x in c.COMMANDS.values() if x.config]"],
               cwd=run, env=env)
  version, *files = where.stdout.split()
  assert wheel.name.startswith(f"mfsample-{version}-")
  assert len(files) == 1 + len(JOB_COMMANDS)
  assert all(pathlib.Path(f).is_relative_to(venv) for f in files), files

  workdir = run / "workdirs" / "tiny"
  job = _run([script, "train", "--config=tiny", f"--workdir={workdir.relative_to(run)}",
              "--config.train.num_steps=4", "--config.train.checkpoint_every=2",
              "--config.densify.stop=3", "--config.eval.save_images=1"], cwd=run, env=env)
  assert "4 steps" in job.stdout and "test PSNR" in job.stdout, job.stdout
  metrics = json.loads((workdir / "metrics.json").read_text())
  assert np.isfinite(metrics["psnr"]) and metrics["num_views"] == 4
  written_by = json.loads((workdir / "config.json").read_text())["_written_by"]
  assert written_by == {"job": "training", "name": "training", "mfsample": version}
  for name in ("point_cloud.ply", "checkpoints/ckpt_00000004.npz",
               "images/test_000_render.png", "images/test_000_uncertainty.png"):
    assert (workdir / name).is_file(), name

  listing = _run([python, "-m", "mfsample", "--help"], cwd=run, env=env)
  assert all(f"  {name} " in listing.stdout for name in cli.COMMANDS)
  # The viewer shows planning jobs: the training workdir is refused at once, in one line.
  viewer = subprocess.run([script, "viewer", f"--workdir={workdir.relative_to(run)}"],
                          cwd=run, env=env, capture_output=True, text=True, timeout=300,
                          check=False)
  assert viewer.returncode == 1 and "Traceback" not in viewer.stderr
  assert "holds a run of the 'training' job, which the viewer does not" in viewer.stderr, (
      viewer.stderr)
