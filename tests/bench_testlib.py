"""Importing the benchmark scripts (absl mains) in a test process."""

import importlib

from absl import flags


def import_script(name):
  """benchmarks/<name>.py as a module, and its flags' defaults.

  Each script is an absl main: its flags (`--out`, `--data`, ...) are global and would
  clash with the next script's, so they are removed again once their defaults are read.
  The measurement functions never read flags.
  """
  module = importlib.import_module(f"benchmarks.{name}")
  owned = list(flags.FLAGS.flags_by_module_dict().get(module.__name__, []))
  defaults = {flag.name: flag.default for flag in owned}
  for flag in owned:
    delattr(flags.FLAGS, flag.name)
  return module, defaults
