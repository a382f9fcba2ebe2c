"""Lego quality: deterministic 3DGS against the mean of rank-2 models (paper: 32.58 vs 32.11 dB).

Trains each variant of the lego config (`configs/train.py:lego`) at --size for --steps on
all 100 training views, in its own workdir under --workdir, with
`mfsample.train.experiment.train_and_evaluate` (the function behind `experiments/train.py`), and
gathers the test PSNR / SSIM / LPIPS of the 200 test views into one table and JSON. Runs
resume from their checkpoints, so a killed benchmark continues where it stopped; finished
variants are only collected. A workdir made with another config is refused, naming the
fields that differ.

  python benchmarks/train_quality.py --size=100 --steps=5000

Variants: "deterministic"; "rank2", the lego config's schedule (samples until the first
opacity reset at step 3000, then the mean, as the authors' code); "rank2_every_step", a
sample at every step (the paper's text).
"""

import copy
import json
import os
import time

from absl import app, flags

# name -> config fields it sets.
VARIANTS = {
    "deterministic": {"sampler.kind": "deterministic"},
    "rank2": {"sampler.kind": "lowrank", "sampler.rank": 2},
    "rank2_every_step": {"sampler.kind": "lowrank", "sampler.rank": 2,
                         "sampler.stochastic_until": None},
}

ROW_FIELDS = ("psnr", "ssim", "lpips", "steps", "live_gaussians", "train_seconds",
              "eval_seconds", "resolution", "num_views", "num_train_views", "sampler", "rank")

_VARIANTS = flags.DEFINE_list("variants", list(VARIANTS), "Variants to run, in this order.")
_SIZE = flags.DEFINE_integer("size", 200, "Image side (lego files are 400 x 400).")
_STEPS = flags.DEFINE_integer("steps", 5000, "Training steps per variant.")
_DATA = flags.DEFINE_string("data", "data/nerf_synthetic/lego", "NeRF Synthetic lego folder.")
_WORKDIR = flags.DEFINE_string("workdir", "workdirs/benchmarks/train_quality",
                               "Parent of the variants' workdirs.")
_OUT = flags.DEFINE_string("out", "workdirs/benchmarks/train_quality.json", "Output JSON.")
_PARALLEL = flags.DEFINE_bool("parallel", False,
                              "Train the variants at the same time, one process each.")
_EXTRA = flags.DEFINE_list("extra", [], "More config fields for every variant, as "
                           "field=value (e.g. model.max_gaussians=40000).")


def lego_config(data, size, steps):
  """The lego training config at `size` x `size` (downscale 400 / size) for `steps` steps."""
  from mfsample.train.config import get_config

  config = get_config("lego")
  config.data.path = data
  config.data.downscale = max(400 // size, 1)
  config.train.num_steps = steps
  config.train.progress = False
  return config


def _set(config, dotted, value):
  *parents, leaf = dotted.split(".")
  node = config
  for p in parents:
    node = node[p]
  if leaf not in node:
    raise KeyError(f"no config field {dotted!r}")
  node[leaf] = value


def parse_overrides(items):
  """{field: value} from "field=value" strings (values read as Python literals when they
  parse as one, else kept as strings); a leading "--config." is accepted."""
  import ast

  out = {}
  for item in items:
    field, sep, text = item.removeprefix("--config.").partition("=")
    if not sep:
      raise ValueError(f"--extra item {item!r} is not field=value")
    try:
      out[field] = ast.literal_eval(text)
    except (ValueError, SyntaxError):
      out[field] = text
  return out


def variant_config(base, name, overrides=None):
  """`base` with the fields of variant `name` (`VARIANTS`), then `overrides` {field: value}."""
  if name not in VARIANTS:
    raise ValueError(f"unknown variant {name!r}; known: {', '.join(VARIANTS)}")
  config = copy.deepcopy(base)
  for field, value in {**VARIANTS[name], **(overrides or {})}.items():
    _set(config, field, value)
  return config


def _comparable(config_dict):
  """What a run's results depend on: its config less the speed-only and display fields (and
  the record of the job and version that wrote it)."""
  from mfsample._json import without_fields
  from mfsample.config_blocks import speed_only_fields
  from mfsample.config_record import WRITTEN_BY

  return without_fields({k: v for k, v in config_dict.items() if k != WRITTEN_BY},
                        speed_only_fields() + ("train.progress",))


def train_variant(config, workdir):
  """Trains and evaluates `config` in `workdir` (resuming it) and returns its metrics row.

  A workdir whose `metrics.json` already reports `config.train.num_steps` steps is only
  read. A workdir with checkpoints of a different config is refused.

  Returns:
    {field: value} for `ROW_FIELDS` from the run's `metrics.json`.
  """
  from mfsample.train import checkpoint as ckpt
  from mfsample.train.experiment import train_and_evaluate
  from mfsample.workdir import differences

  new = _comparable(json.loads(config.to_json_best_effort()))
  config_path = os.path.join(workdir, "config.json")
  metrics_path = os.path.join(workdir, "metrics.json")
  started = ckpt.list_checkpoints(os.path.join(workdir, "checkpoints"))
  if started and os.path.exists(config_path):
    with open(config_path) as f:
      old = _comparable(json.load(f))
    if old != new:
      raise ValueError(f"{workdir} holds a run of a different config (differences: "
                       f"{', '.join(differences(old, new))}); use another --workdir or "
                       "remove that one.")
  done = False
  if started and os.path.exists(metrics_path):
    with open(metrics_path) as f:
      done = json.load(f).get("steps") == int(config.train.num_steps)
  if not done:
    train_and_evaluate(config, workdir)
  with open(metrics_path) as f:
    metrics = json.load(f)
  return {k: metrics.get(k) for k in ROW_FIELDS}


def run(base, names, workdir, *, overrides=None, parallel=False):
  """{name: metrics row} of every variant in `names` trained from `base` in
  `workdir/<name>`; `parallel` trains them at once, one fresh process each."""
  configs = {name: variant_config(base, name, overrides) for name in names}
  dirs = {name: os.path.join(workdir, name) for name in names}
  if not parallel:
    return {name: train_variant(configs[name], dirs[name]) for name in names}
  import concurrent.futures
  import multiprocessing

  # Spawned, not forked: JAX's runtime threads do not survive a fork.
  context = multiprocessing.get_context("spawn")
  with concurrent.futures.ProcessPoolExecutor(len(names), mp_context=context) as pool:
    futures = {name: pool.submit(train_variant, configs[name], dirs[name]) for name in names}
    return {name: futures[name].result() for name in names}


def main(argv):
  del argv
  from mfsample._bench import machine, require_scene_folder
  from mfsample._json import write_json

  try:
    require_scene_folder(_DATA.value, "--data")
  except FileNotFoundError as error:
    raise app.UsageError(str(error)) from error
  base = lego_config(_DATA.value, _SIZE.value, _STEPS.value)
  overrides = parse_overrides(_EXTRA.value)
  for name in _VARIANTS.value:  # fail on a bad name or field before any training
    variant_config(base, name, overrides)
  started = time.time()
  rows = run(base, _VARIANTS.value, _WORKDIR.value, overrides=overrides,
             parallel=_PARALLEL.value)
  print(f"\n{'variant':>16} | {'PSNR':>6} | {'SSIM':>6} | {'LPIPS':>6} | steps | "
        f"Gaussians | train min")
  for name, r in rows.items():
    lp = float("nan") if r["lpips"] is None else r["lpips"]
    print(f"{name:>16} | {r['psnr']:6.2f} | {r['ssim']:6.4f} | {lp:6.4f} | {r['steps']:5d} | "
          f"{r['live_gaussians']:9d} | {r['train_seconds'] / 60:9.1f}")
  write_json(_OUT.value, {"machine": machine(), "variants": rows,
                          "wall_seconds_this_call": time.time() - started,
                          "size": _SIZE.value, "steps": _STEPS.value, "data": _DATA.value,
                          "workdir": _WORKDIR.value, "parallel": _PARALLEL.value,
                          "extra": _EXTRA.value})
  print(f"saved {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
