"""Milliseconds per training step of every sampler on one scene, and peak memory.

Every variant starts from the same initial state (NeRF Synthetic lego at --size with the
lego config's random initial cloud, or a synthetic scene when --data holds no lego),
compiles the step, runs `--warmup` steps, then times `--steps` steps (median). Variants
run in interleaved rounds and each ratio to deterministic is taken within a round, so a
change in the machine's load between rounds does not bias the ratios. Densification is
off: this measures the jitted step (paper Tab. 4 measures the same thing per iteration).

Each measurement runs in a fresh subprocess, so its peak RSS is its own and no compilation
cache leaks between variants; `measure_variant` is the same measurement in this process.

  PYTHONPATH=. python benchmarks/train_step.py --rounds=3
  PYTHONPATH=. python benchmarks/train_step.py --clock=process  # on a CPU shared with others

A variant `NAME@C` composites C chunks per loop step (`render.chunks_per_step`, a speed
knob) and takes its ratio to `deterministic@C`; every variant also gets its ratio to the
first one listed (`vs_first`, within a round), which compares the C of a sweep. On a GPU,
where small steps are bound by launch latency, sweep it at the paper's scale:

  PYTHONPATH=. python benchmarks/train_step.py --size=400 --points=100000 --rounds=1 \
      --variants=deterministic@16,deterministic@64,deterministic@256,deterministic@1024
"""

import copy
import dataclasses
import json
import os
import resource
import statistics
import subprocess
import sys
import time

from absl import app, flags

VARIANTS = ("deterministic", "diagonal", "block", "rank1", "rank2", "rank4", "rank10")

_VARIANTS = flags.DEFINE_list(
    "variants", list(VARIANTS),
    "Variants: deterministic, diagonal, block, rankK; each optionally @C, compositing C "
    "chunks per step (render.chunks_per_step, default the config's), e.g. rank2@256.")
_ROUNDS = flags.DEFINE_integer("rounds", 2, "Interleaved rounds over all variants.")
_STEPS = flags.DEFINE_integer("steps", 20, "Timed steps per variant and round.")
_WARMUP = flags.DEFINE_integer("warmup", 3, "Untimed steps after compilation.")
_SIZE = flags.DEFINE_integer("size", 200, "Image side in pixels (lego downscale 400/size).")
_POINTS = flags.DEFINE_integer("points", 10_000, "Gaussians of the initial cloud.")
_SAMPLES = flags.DEFINE_integer("samples", 1, "M, samples per step.")
_DATA = flags.DEFINE_string(
    "data", "data/nerf_synthetic/lego",
    "NeRF Synthetic lego folder (400 x 400 files); a synthetic scene is timed if absent.")
_FROM = flags.DEFINE_string(
    "from_checkpoints", None,
    "Checkpoint folder of a trained lego run (experiments/train.py "
    "--config=configs/train.py:lego, same --size): start every variant from its mean "
    "Gaussians (with fresh B_hat) instead of the random initial cloud, i.e. time "
    "late-training steps.")
_CLOCK = flags.DEFINE_enum(
    "clock", "wall", ["wall", "process"],
    "What a step's time is: wall-clock, or the CPU time of the measuring process (all its "
    "threads: the work done, steadier than wall-clock on a machine shared with other jobs, "
    "and no measure of speed on a GPU).")
_OUT = flags.DEFINE_string("out", "workdirs/benchmarks/train_step.json", "Output JSON.")
_CHILD = flags.DEFINE_string("child", None, "Internal: run one variant and print JSON.")


def base_config(data, size, points, samples):
  """(training config, scene name) every variant starts from.

  The lego config at `size` x `size` (downscale 400 / size) with `points` initial points
  and M = `samples`; when `data` holds no NeRF Synthetic scene, the same at `size` on a
  synthetic scene of 2000 random Gaussians seen by 16 views (scene name "synthetic").
  """
  from configs import train

  config = train.get_config("lego")
  config.sampler.num_samples = samples
  config.model.init_points = points
  config.data.path = data
  config.data.downscale = max(400 // size, 1)
  if os.path.isfile(os.path.join(data, "transforms_train.json")):
    return config, "lego"
  config.data.kind = "synthetic"
  config.data.init_bounds = (-0.8, 0.8)
  syn = config.data.synthetic
  syn.num_gaussians, syn.width, syn.height, syn.sh_degree = 2000, size, size, 3
  syn.num_train, syn.num_test = 16, 1
  return config, "synthetic"


def variant_config(base, variant):
  """`base` set up to time `variant` ("deterministic", "diagonal", "block" or "rankK",
  optionally "@C" for C chunks per compositing step), densification off."""
  config = copy.deepcopy(base)
  name, _, chunks_per_step = variant.partition("@")
  if chunks_per_step:
    config.render.chunks_per_step = int(chunks_per_step)
  if name == "deterministic":
    config.sampler.kind = "deterministic"
  elif name in ("diagonal", "block"):
    config.sampler.kind = name
    config.sampler.rank = 2  # block: one rank-2 block per Gaussian (as many floats as rank 2)
  elif name.startswith("rank") and name[4:].isdigit():
    config.sampler.kind = "lowrank"
    config.sampler.rank = int(name[4:])
  else:
    raise ValueError(f"unknown variant {variant!r}: expected deterministic, diagonal, block "
                     "or rankK, optionally followed by @C")
  config.densify.start = 10**9  # no densification: time the jitted step alone
  config.train.progress = False
  return config


def _from_trained(fresh, setup, checkpoint_dir):
  """`fresh` with the mean Gaussians of the newest checkpoint in `checkpoint_dir` and fresh
  B_hat entries of `fresh`'s sampler (only the mean is taken: any sampler may have trained)."""
  import jax
  import jax.numpy as jnp
  import numpy as np

  from mfsample.model import Model, Params, init_spread
  from mfsample.train import checkpoint as ckpt
  from mfsample.train.step import init_train_state

  paths = ckpt.list_checkpoints(checkpoint_dir)
  if not paths:
    raise FileNotFoundError(f"--from_checkpoints={checkpoint_dir!r} holds no checkpoint")
  with np.load(paths[-1]) as data:
    arrays = {k: data[k] for k in data.files if k != "__meta__"}
  mean = {g: jnp.asarray(arrays[f".model.params.mean['{g}']"])
          for g in fresh.model.params.mean}
  mask = np.asarray(arrays[".model.mask"])
  capacity, live = mask.shape[0], int(mask.sum())
  shapes = {g: v.shape[1:] for g, v in mean.items()}
  spread, signs = init_spread(np.random.default_rng(0), live, shapes, setup.spec,
                              setup.init_scales)

  def pad(x):
    return jnp.asarray(np.concatenate([x, np.zeros((capacity - live,) + x.shape[1:], x.dtype)]))

  model = Model(Params(mean, {g: pad(v) for g, v in spread.items()}),
                {g: pad(v) for g, v in signs.items()}, jnp.asarray(mask),
                jnp.asarray(int(arrays[".model.sh_degree"]), jnp.int32), setup.spec)
  return init_train_state(model, setup.step_config, jax.random.PRNGKey(0))


def _peak_rss_mb():
  peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
  return peak / (2**20 if sys.platform == "darwin" else 1024.0)  # bytes on macOS, KiB on Linux


def measure_variant(config, *, steps, warmup, from_checkpoints=None, clock="wall"):
  """Times the jitted training step of `config` in this process.

  The step is compiled, run `warmup` times untimed, then `steps` times, each call timed to
  completion (`block_until_ready`). A step whose render overflows the intersection budget
  grows it and is re-run, as the training loop does; it is not timed.

  Args:
    config: a training config (`variant_config`).
    steps: timed steps.
    warmup: untimed steps after compilation.
    from_checkpoints: optional checkpoint folder whose mean Gaussians replace the random
      initial cloud.
    clock: "wall" (`time.perf_counter`) or "process" (`time.process_time`: CPU time of
      this process, every thread).

  Returns:
    {ms_median, ms_min, ms_all [steps], peak_rss_mb (of this process so far: a variant's
    own only in a fresh process), seconds_total, capacity, live, budget, chunks_per_step,
    params_per_gaussian (floats trained per Gaussian: mean and B_hat), resolution}.
  """
  import jax
  import jax.numpy as jnp
  import numpy as np

  from mfsample.data import datasets as data_lib
  from mfsample.renderer.budget import fit_budget
  from mfsample.train import loop
  from mfsample.train.step import make_train_step

  dataset = data_lib.load_dataset(config.data)
  views = data_lib.to_device(dataset.train)
  setup = loop.make_setup(config, dataset.train)
  state = loop.init_state(config, setup, dataset.bounds)
  if from_checkpoints:
    state = _from_trained(state, setup, from_checkpoints)
  m = setup.step_config.num_samples
  fn = make_train_step(setup.step_config)
  timer = time.process_time if clock == "process" else time.perf_counter
  t0 = time.perf_counter()
  step, times = 0, []
  while step < warmup + steps:
    view = jnp.int32(loop.view_for_step(0, step, len(views)))
    rows = setup.sobol[step * m:(step + 1) * m]
    t = timer()
    new_state, metrics = fn(state, views.images, views.cameras, view, rows)
    jax.block_until_ready(new_state)
    dt = timer() - t
    if bool(metrics.overflow):
      settings = fit_budget(setup.step_config.settings, metrics)
      setup = setup._replace(step_config=dataclasses.replace(setup.step_config,
                                                             settings=settings))
      fn = make_train_step(setup.step_config)
      continue
    state = new_state
    if step >= warmup:
      times.append(dt)
    step += 1
  return {
      "ms_median": 1e3 * statistics.median(times), "ms_min": 1e3 * min(times),
      "ms_all": [1e3 * t for t in times], "peak_rss_mb": _peak_rss_mb(),
      "seconds_total": time.perf_counter() - t0,
      "capacity": int(state.model.capacity), "live": int(np.sum(np.asarray(state.model.mask))),
      "budget": setup.step_config.settings.max_intersections,
      "chunks_per_step": setup.step_config.settings.chunks_per_step,
      "params_per_gaussian": int(sum(np.prod(x.shape[1:]) for x in
                                     jax.tree.leaves(state.model.params))),
      "resolution": int(views.images.shape[1]),
  }


def run_rounds(variants, rounds, measure, log=print):
  """`rounds` interleaved passes over `variants`: [{variant: measure(variant)}] per round,
  each result with the load average seen before it."""
  from mfsample._bench import load_average

  out = []
  for r in range(rounds):
    results = {}
    for variant in variants:
      load = load_average()
      res = dict(measure(variant), variant=variant, load_before=list(load))
      results[variant] = res
      log(f"round {r} {variant:>16}: {res['ms_median']:8.1f} ms/step  "
          f"peak {res['peak_rss_mb']:7.0f} MB  (load {load[0]:.2f})")
    out.append(results)
  return out


def summarize(variants, rounds):
  """{variant: row} from `run_rounds`' output.

  Each row: ms_per_step (median over rounds), ms_rounds, peak_rss_mb (max over rounds),
  params_per_gaussian, chunks_per_step, vs_first (median over rounds of the ratio to the
  first variant in the same round) and, where `deterministic[@C]` with the same C was
  measured, ratio (the same, against it).
  """
  table = {}
  first = variants[0]

  def within_rounds(variant, base):
    return statistics.median(r[variant]["ms_median"] / r[base]["ms_median"] for r in rounds)

  for variant in variants:
    ms = [r[variant]["ms_median"] for r in rounds]
    row = {"ms_per_step": statistics.median(ms), "ms_rounds": ms,
           "peak_rss_mb": max(r[variant]["peak_rss_mb"] for r in rounds),
           "params_per_gaussian": rounds[0][variant]["params_per_gaussian"],
           "chunks_per_step": rounds[0][variant]["chunks_per_step"]}
    _, at, chunks_per_step = variant.partition("@")
    base = f"deterministic{at}{chunks_per_step}"  # the same loop step as `variant`
    if base in rounds[0]:
      row["ratio"] = within_rounds(variant, base)
    row["vs_first"] = within_rounds(variant, first)
    table[variant] = row
  return table


def _child_flags():
  """The flags a child needs to rebuild this run's configs."""
  args = [f"--steps={_STEPS.value}", f"--warmup={_WARMUP.value}", f"--size={_SIZE.value}",
          f"--points={_POINTS.value}", f"--samples={_SAMPLES.value}", f"--data={_DATA.value}",
          f"--clock={_CLOCK.value}"]
  if _FROM.value:
    args.append(f"--from_checkpoints={_FROM.value}")
  return args


def _measure_in_subprocess(variant):
  env = dict(os.environ, PYTHONPATH=os.pathsep.join([".", os.environ.get("PYTHONPATH", "")]))
  out = subprocess.run([sys.executable, __file__, f"--child={variant}", *_child_flags()],
                       env=env, capture_output=True, text=True, check=False)
  if out.returncode:
    raise RuntimeError(f"{variant} failed:\n{out.stderr[-3000:]}")
  return json.loads(out.stdout.strip().splitlines()[-1])


def _measure_here(variant):
  base, _ = base_config(_DATA.value, _SIZE.value, _POINTS.value, _SAMPLES.value)
  return measure_variant(variant_config(base, variant), steps=_STEPS.value,
                         warmup=_WARMUP.value, from_checkpoints=_FROM.value,
                         clock=_CLOCK.value)


def main(argv):
  del argv
  if _CHILD.value:
    print(json.dumps(_measure_here(_CHILD.value)))
    return
  from mfsample._bench import NERF_SYNTHETIC_HINT, load_average

  for variant in _VARIANTS.value:  # fail on a typo before any child starts
    variant_config(base_config(_DATA.value, _SIZE.value, 1, 1)[0], variant)
  _, scene = base_config(_DATA.value, _SIZE.value, _POINTS.value, _SAMPLES.value)
  if scene != "lego":
    print(f"No lego at --data={_DATA.value!r}: timing a synthetic scene of 2000 random "
          f"Gaussians instead. " + NERF_SYNTHETIC_HINT.format(flag="--data"), flush=True)
  rounds = run_rounds(_VARIANTS.value, _ROUNDS.value, _measure_in_subprocess,
                      log=lambda line: print(line, flush=True))
  table = summarize(_VARIANTS.value, rounds)
  print(f"\n{'variant':>16} | {'ms/step':>8} | {'ratio':>6} | {'vs_first':>8} | "
        f"{'peak RSS MB':>11} | params/G")
  for variant, row in table.items():
    print(f"{variant:>16} | {row['ms_per_step']:8.1f} | {row.get('ratio', float('nan')):6.3f} | "
          f"{row['vs_first']:8.3f} | {row['peak_rss_mb']:11.0f} | {row['params_per_gaussian']}")
  first = rounds[0][_VARIANTS.value[0]]
  from mfsample._bench import machine  # after the children: they had the device to themselves
  from mfsample._json import write_json

  write_json(_OUT.value, {"machine": machine(), "scene": scene, "table": table,
                          "rounds": rounds, "resolution": first["resolution"],
                          "from_checkpoints": _FROM.value, "live_gaussians": first["live"],
                          "points": _POINTS.value, "samples": _SAMPLES.value,
                          "steps": _STEPS.value, "warmup": _WARMUP.value,
                          "clock": _CLOCK.value,
                          "load_end": list(load_average())})
  print(f"saved {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
