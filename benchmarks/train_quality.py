"""Lego quality: the deterministic model vs the rank-2 mean (paper: 32.58 vs 32.11 dB).

Trains each variant with `experiments/train.py` (configs/train_lego.py plus a few
overrides) in its own workdir, then gathers their `metrics.json` into one table and JSON.
Runs resume from their checkpoints, so a killed benchmark continues where it stopped;
finished variants are only collected.

  PYTHONPATH=. python benchmarks/train_quality.py --size=100 --steps=5000 --parallel \
      --workdir=workdirs/quality --out=results/train_quality.json
"""

import json
import os
import subprocess
import sys
import time

from absl import app, flags

# name -> config overrides. "rank2" keeps configs/train_lego.py's schedule (samples until
# the first opacity reset, as the authors' code); "rank2_every_step" samples at every step
# (the paper's text).
VARIANTS = {
    "deterministic": ["--config.sampler.kind=deterministic"],
    "rank2": ["--config.sampler.kind=lowrank", "--config.sampler.rank=2"],
    "rank2_every_step": ["--config.sampler.kind=lowrank", "--config.sampler.rank=2",
                         f"--config.sampler.stochastic_until={2**31 - 1}"],
}

_VARIANTS = flags.DEFINE_list("variants", list(VARIANTS), "Variants to run.")
_SIZE = flags.DEFINE_integer("size", 200, "Image side (lego files are 400 x 400).")
_STEPS = flags.DEFINE_integer("steps", 5000, "Training steps per variant.")
_DATA = flags.DEFINE_string("data", "../shared/data/lego", "NeRF Synthetic lego folder.")
_WORKDIR = flags.DEFINE_string("workdir", "workdirs/quality", "Parent of the run workdirs.")
_OUT = flags.DEFINE_string("out", "results/train_quality.json", "Output JSON.")
_PARALLEL = flags.DEFINE_bool("parallel", False, "Run the variants at the same time.")
_EXTRA = flags.DEFINE_list("extra", [], "More --config.* overrides for every variant.")


def _command(name):
  return [sys.executable, "experiments/train.py", "--config=configs/train.py:lego",
          f"--workdir={os.path.join(_WORKDIR.value, name)}",
          f"--config.data.path={_DATA.value}",
          f"--config.data.downscale={400 // _SIZE.value}",
          f"--config.train.num_steps={_STEPS.value}", "--config.train.progress=False",
          *VARIANTS[name], *_EXTRA.value]


def main(argv):
  del argv
  env = dict(os.environ, PYTHONPATH=os.pathsep.join([".", os.environ.get("PYTHONPATH", "")]))
  os.makedirs(_WORKDIR.value, exist_ok=True)
  procs, started = {}, time.time()
  for name in _VARIANTS.value:
    log = open(os.path.join(_WORKDIR.value, f"{name}.log"), "a")  # noqa: SIM115
    procs[name] = (subprocess.Popen(_command(name), env=env, stdout=log, stderr=log), log)
    print(f"started {name}: {' '.join(_command(name))}", flush=True)
    if not _PARALLEL.value:
      procs[name][0].wait()
  for name, (proc, log) in procs.items():
    if proc.wait():
      raise RuntimeError(f"{name} failed; see {log.name}")
    log.close()

  rows = {}
  for name in _VARIANTS.value:
    with open(os.path.join(_WORKDIR.value, name, "metrics.json")) as f:
      m = json.load(f)
    rows[name] = {k: m[k] for k in ("psnr", "ssim", "lpips", "steps", "live_gaussians",
                                    "train_seconds", "eval_seconds", "resolution",
                                    "num_views", "num_train_views")}
  print(f"\n{'variant':>14} | {'PSNR':>6} | {'SSIM':>6} | {'LPIPS':>6} | steps | "
        f"Gaussians | train min")
  for name, r in rows.items():
    lp = float("nan") if r["lpips"] is None else r["lpips"]
    print(f"{name:>14} | {r['psnr']:6.2f} | {r['ssim']:6.4f} | {lp:6.4f} | {r['steps']:5d} | "
          f"{r['live_gaussians']:9d} | {r['train_seconds'] / 60:9.1f}")
  from mfsample._json import write_json
  write_json(_OUT.value, {"variants": rows, "wall_seconds_this_call": time.time() - started,
                          "size": _SIZE.value, "steps": _STEPS.value,
                          "parallel": _PARALLEL.value, "extra": _EXTRA.value})
  print(f"saved {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
