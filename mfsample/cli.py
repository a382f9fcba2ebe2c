"""The `mfsample` command of an installed package: every job, the viewer and render-ply.

For example::

  mfsample train --config=tiny --workdir=workdirs/tiny
  mfsample camera-planning --workdir=workdirs/camera_planning --config=lego,rounds2000
  mfsample next-views --config=colmap,posthoc --workdir=workdirs/garden \\
      --config.data.path=~/captures/garden --config.posthoc.ply=~/models/garden/point_cloud.ply
  mfsample viewer --workdir=workdirs/camera_planning

`python -m mfsample ...` is the same command. A job's flags are those of its script in a
clone's `experiments/` (`mfsample.jobs.main`): `--workdir`, `--config` and
`--config.field=value` overrides. `--config` names the variants of the job's config file
shipped in the package (`mfsample/configs/`), comma-separated (`--config=tiny`,
`--config=lego,rounds2000`); without it the job runs its default config. A value whose file
part ends in `.py`, `--config=path.py[:variants]`, is a config file as `experiments/` take
it (a clone's `configs/`, or a file of one's own).
"""

import dataclasses
import importlib
import re
import sys


@dataclasses.dataclass(frozen=True)
class Command:
  """A sub-command.

  Attributes:
    summary: one line for `mfsample --help`.
    job: module holding the job's `JOB` (`mfsample.jobs.Job`); "" for a program that is no
      job (the viewer), whose module has `main()`.
    config: the job's config file in `mfsample/configs/` (module name), "" for no job.
  """

  summary: str
  job: str
  config: str = ""


COMMANDS = {
    "train": Command("train a stochastic Gaussian field and evaluate it",
                     "mfsample.train.experiment", "train"),
    "camera-planning": Command("active camera planning: every strategy, rounds, figures",
                               "mfsample.planning.runner", "camera_planning"),
    "light-planning": Command("active illumination planning: every light strategy, figures",
                              "mfsample.lighting.protocol", "light_planning"),
    "uncertainty-quality": Command("AUSE against exact depth error; U against the error",
                                   "mfsample.quality.runner", "uncertainty_quality"),
    "next-views": Command("uncertainty maps and the next views of a capture or a .ply",
                          "mfsample.your_data.runner", "next_views"),
    "viewer": Command("a job's workdir in the browser (the capture planner)",
                      "mfsample.viewer.command"),
    "render-ply": Command("any 3DGS .ply, or a per-Gaussian property of it, rendered to PNG",
                          "mfsample.your_data.render_ply_command"),
}

HELP = ("-h", "--help", "-help", "--helpshort", "-?")
_CONFIG_FLAG = re.compile(r"^--?config(=|$)")


class UsageError(ValueError):
  """A command line that names no command, or a variant its job does not have."""


def config_module(command: Command):
  """The packaged config module of a job's command."""
  return importlib.import_module(f"mfsample.configs.{command.config}")


def config_file(command: Command):
  """The path of a job's packaged config file (what `--config` loads)."""
  return config_module(command).__file__


def resolve_config(name: str, command: Command, spec: str):
  """The `--config` value that absl loads for `spec`: a `path.py[:variants]` as given, else
  the packaged config file with `spec` as its variants (checked against the job's).

  Raises:
    UsageError: a variant the job does not have (named, with the known ones).
  """
  if spec.split(":", 1)[0].endswith(".py"):
    return spec
  known = config_module(command).VARIANTS
  for variant in filter(None, (v.strip() for v in spec.split(","))):
    if variant not in known:
      raise UsageError(f"mfsample {name}: --config: unknown variant {variant!r}; known: "
                       f"{', '.join(known)} (comma-separated), or a config file path.py")
  return f"{config_file(command)}:{spec}"


def job_argv(name: str, args):
  """The argv that `mfsample.jobs.main` parses for `mfsample <name> <args>`: `--config`
  resolved (`resolve_config`), or the default config inserted first when it is absent."""
  command = COMMANDS[name]
  args = list(args)
  for i, arg in enumerate(args):
    match = _CONFIG_FLAG.match(arg)
    if match is None:
      continue
    if match.group(1) == "=":
      args[i] = "--config=" + resolve_config(name, command, arg.split("=", 1)[1])
    elif i + 1 < len(args):  # `--config VALUE`
      args[i + 1] = resolve_config(name, command, args[i + 1])
    return [f"mfsample {name}", *args]
  # First, so that overrides (`--config.x=...`) come after the config, as absl requires.
  return [f"mfsample {name}", f"--config={config_file(command)}", *args]


def usage():
  """`mfsample --help`: the commands."""
  width = max(map(len, COMMANDS))
  lines = ["usage: mfsample COMMAND [flags]   (or: python -m mfsample COMMAND [flags])", "",
           "commands:"]
  lines += [f"  {name:<{width}}  {c.summary}" for name, c in COMMANDS.items()]
  lines += ["", "mfsample COMMAND --help lists a command's flags and variants; a job's flags:",
            "  --workdir=DIR              where it writes (running again resumes)",
            "  --config=VARIANTS          the job's variants, comma-separated (default: none)",
            "  --config=FILE.py[:VARIANTS]  a config file instead",
            "  --config.FIELD=VALUE       an override of one field"]
  return "\n".join(lines)


def command_help(name: str):
  """`mfsample <name> --help`: its usage and its config's (or program's) docstring."""
  command = COMMANDS[name]
  if not command.config:
    return importlib.import_module(command.job).__doc__.strip()
  return "\n".join([
      f"usage: mfsample {name} --workdir=DIR [--config=VARIANTS | --config=FILE.py[:VARIANTS]]"
      " [--config.FIELD=VALUE ...]", "", config_module(command).__doc__.strip(), "",
      "--helpfull lists every flag."])


def _usage_error(message):
  """Ends the command as the jobs end on a user's error: one line, exit code 2."""
  print(message, file=sys.stderr)
  sys.exit(2)


def main(argv=None):
  """The `mfsample` console script (and `python -m mfsample`)."""
  argv = list(sys.argv if argv is None else argv)
  if len(argv) < 2 or argv[1] in HELP or argv[1] == "help":
    print(usage())
    return
  name, args = argv[1], argv[2:]
  if name not in COMMANDS:
    _usage_error(f"mfsample: unknown command {name!r}; commands: {', '.join(COMMANDS)} "
                 "(mfsample --help)")
  if any(arg in HELP for arg in args):
    print(command_help(name))
    return
  command = COMMANDS[name]
  if not command.config:
    sys.argv = [f"mfsample {name}", *args]
    importlib.import_module(command.job).main()
    return
  try:
    sys.argv = job_argv(name, args)
  except UsageError as e:
    _usage_error(str(e))
  from mfsample import jobs

  jobs.main(importlib.import_module(command.job).JOB)

