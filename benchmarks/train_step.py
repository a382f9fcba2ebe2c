"""Milliseconds per training step of every sampler on one scene, and peak memory.

Each variant runs in a fresh subprocess (so peak RSS is its own and compilation caches do
not leak between variants): it builds the same initial state (lego at 200 x 200 with the
lego config's random initial cloud, or a synthetic scene when lego is absent), compiles the
step, runs `--warmup` steps, then times `--steps` steps (median). Variants are run in
interleaved rounds and each ratio to deterministic is taken within a round, so a change in
the machine's load between rounds does not bias the ratios. Densification is off: this
measures the jitted step (paper Tab. 4 measures the same thing per iteration).

  PYTHONPATH=. python benchmarks/train_step.py --rounds=2 --out=results/train_step.json

A variant `NAME@C` composites C chunks per loop step (`render.chunks_per_step`, a speed
knob) and takes its ratio to `deterministic@C`; every variant also gets its ratio to the
first one listed (`vs_first`, within a round), which compares the C of a sweep. On a GPU,
where small steps are bound by launch latency, sweep it at the paper's scale:

  PYTHONPATH=. python benchmarks/train_step.py --size=400 --points=100000 --rounds=1 \
      --variants=deterministic@16,deterministic@64,deterministic@256,deterministic@1024
"""

import dataclasses
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time

from absl import app, flags

_VARIANTS = flags.DEFINE_list(
    "variants", ["deterministic", "diagonal", "block", "rank1", "rank2", "rank4", "rank10"],
    "Variants: deterministic, diagonal, block, rankK; each optionally @C, compositing C "
    "chunks per step (render.chunks_per_step, default the config's), e.g. rank2@256.")
_ROUNDS = flags.DEFINE_integer("rounds", 2, "Interleaved rounds over all variants.")
_STEPS = flags.DEFINE_integer("steps", 20, "Timed steps per variant and round.")
_WARMUP = flags.DEFINE_integer("warmup", 3, "Untimed steps after compilation.")
_SIZE = flags.DEFINE_integer("size", 200, "Image side in pixels (lego downscale 400/size).")
_POINTS = flags.DEFINE_integer("points", 10_000, "Gaussians of the initial cloud.")
_SAMPLES = flags.DEFINE_integer("samples", 1, "M, samples per step.")
_DATA = flags.DEFINE_string("data", "../shared/data/lego",
                            "NeRF Synthetic lego folder (synthetic scene if absent).")
_FROM = flags.DEFINE_string(
    "from_checkpoints", None,
    "Checkpoint folder of a trained lego run (configs/train_lego.py, same --size): start "
    "every variant from its mean Gaussians (with fresh B_hat) instead of the random initial "
    "cloud, i.e. time late-training steps.")
_OUT = flags.DEFINE_string("out", "results/train_step.json", "Output JSON.")
_CHILD = flags.DEFINE_string("child", None, "Internal: run one variant and print JSON.")


def _config(cell):
  from configs import train

  config = train.get_config("lego")
  variant, _, chunks_per_step = cell.partition("@")
  if chunks_per_step:
    config.render.chunks_per_step = int(chunks_per_step)
  if variant == "deterministic":
    config.sampler.kind = "deterministic"
  elif variant in ("diagonal", "block"):
    config.sampler.kind = variant
    config.sampler.rank = 2  # block: one rank-2 block per Gaussian (same size as rank 2)
  elif variant.startswith("rank"):
    config.sampler.kind = "lowrank"
    config.sampler.rank = int(variant[4:])
  else:
    raise ValueError(f"unknown variant {variant}")
  config.sampler.num_samples = _SAMPLES.value
  config.model.init_points = _POINTS.value
  config.data.path = _DATA.value
  config.data.downscale = max(400 // _SIZE.value, 1)
  config.densify.start = 10**9  # no densification: time the jitted step alone
  config.train.progress = False
  return config


def _from_trained(config, setup, dataset, fresh):
  """`fresh`'s sampler with the mean Gaussians of the newest checkpoint in --from_checkpoints."""
  import jax
  import jax.numpy as jnp
  import numpy as np

  from mfsample.model import Model, Params, init_spread
  from mfsample.train import checkpoint as ckpt
  from mfsample.train import loop
  from mfsample.train.step import init_train_state

  path = ckpt.list_checkpoints(_FROM.value)[-1]
  meta = ckpt.read_meta(path)
  with np.load(path) as data:
    arrays = {k: data[k] for k in data.files if k != "__meta__"}
  mean = {g: jnp.asarray(arrays[f".model.params.mean['{g}']"])
          for g in fresh.model.params.mean}
  mask = np.asarray(arrays[".model.mask"])
  capacity, live = mask.shape[0], int(mask.sum())
  shapes = {g: v.shape[1:] for g, v in mean.items()}
  spread, signs = init_spread(np.random.default_rng(0), live, shapes, setup.spec,
                              setup.init_scales)
  pad = lambda x: jnp.asarray(np.concatenate([x, np.zeros((capacity - live,) + x.shape[1:],
                                                         x.dtype)]))
  model = Model(Params(mean, {g: pad(v) for g, v in spread.items()}),
                {g: pad(v) for g, v in signs.items()}, jnp.asarray(mask),
                jnp.asarray(int(arrays[".model.sh_degree"]), jnp.int32), setup.spec)
  del config, dataset, loop, meta
  return init_train_state(model, setup.step_config, jax.random.PRNGKey(0))._replace(
      step=jnp.int32(0))


def _child(variant):
  import jax
  import jax.numpy as jnp
  import numpy as np

  from mfsample.renderer.budget import fit_budget
  from mfsample.train import data as data_lib
  from mfsample.train import loop
  from mfsample.train.step import make_train_step

  config = _config(variant)
  if not os.path.isdir(config.data.path):
    config.data.kind = "synthetic"
    config.data.init_bounds = (-0.8, 0.8)
    syn = config.data.synthetic
    syn.num_gaussians, syn.width, syn.height, syn.sh_degree = 2000, _SIZE.value, _SIZE.value, 3
    syn.num_train, syn.num_test = 16, 1
  dataset = data_lib.load_dataset(config.data)
  views = data_lib.to_device(dataset.train)
  setup = loop.make_setup(config, dataset.train)
  state = loop.init_state(config, setup, dataset.bounds)
  if _FROM.value:
    state = _from_trained(config, setup, dataset, state)
  m = setup.step_config.num_samples
  fn = make_train_step(setup.step_config)
  # Grow the budget until no step of the warm-up overflows (as the loop does).
  t0 = time.perf_counter()
  step, times = 0, []
  while step < _WARMUP.value + _STEPS.value:
    view = jnp.int32(loop.view_for_step(0, step, len(views)))
    rows = setup.sobol[step * m:(step + 1) * m]
    t = time.perf_counter()
    new_state, metrics = fn(state, views.images, views.cameras, view, rows)
    jax.block_until_ready(new_state)
    dt = time.perf_counter() - t
    if bool(metrics.overflow):
      settings = fit_budget(setup.step_config.settings, metrics)
      setup = setup._replace(step_config=dataclasses.replace(setup.step_config,
                                                             settings=settings))
      fn = make_train_step(setup.step_config)
      continue
    state = new_state
    if step >= _WARMUP.value:
      times.append(dt)
    step += 1
  usage = resource.getrusage(resource.RUSAGE_SELF)
  print(json.dumps({
      "variant": variant, "ms_median": 1e3 * statistics.median(times),
      "ms_min": 1e3 * min(times), "ms_all": [1e3 * t for t in times],
      "peak_rss_mb": usage.ru_maxrss / 1024.0, "seconds_total": time.perf_counter() - t0,
      "capacity": int(state.model.capacity), "live": int(np.sum(np.asarray(state.model.mask))),
      "budget": setup.step_config.settings.max_intersections,
      "chunks_per_step": setup.step_config.settings.chunks_per_step,
      "params_per_gaussian": int(sum(np.prod(x.shape[1:]) for x in
                                     jax.tree.leaves(state.model.params))),
      "resolution": int(views.images.shape[1]),
  }))


def _load():
  try:
    return os.getloadavg()
  except OSError:
    return (float("nan"),) * 3


def main(argv):
  del argv
  if _CHILD.value:
    _child(_CHILD.value)
    return
  env = dict(os.environ, PYTHONPATH=os.pathsep.join([".", os.environ.get("PYTHONPATH", "")]))
  passthrough = [f"--steps={_STEPS.value}", f"--warmup={_WARMUP.value}",
                 f"--size={_SIZE.value}", f"--points={_POINTS.value}",
                 f"--samples={_SAMPLES.value}", f"--data={_DATA.value}"]
  if _FROM.value:
    passthrough.append(f"--from_checkpoints={_FROM.value}")
  rounds = []
  for r in range(_ROUNDS.value):
    results = {}
    for variant in _VARIANTS.value:
      load = _load()
      out = subprocess.run([sys.executable, __file__, f"--child={variant}", *passthrough],
                           env=env, capture_output=True, text=True, check=False)
      if out.returncode:
        raise RuntimeError(f"{variant} failed:\n{out.stderr[-3000:]}")
      res = json.loads(out.stdout.strip().splitlines()[-1])
      res["load_before"] = load
      results[variant] = res
      print(f"round {r} {variant:>16}: {res['ms_median']:8.1f} ms/step  "
            f"peak {res['peak_rss_mb']:7.0f} MB  (load {load[0]:.2f})", flush=True)
    rounds.append(results)

  table = {}
  first_variant = _VARIANTS.value[0]
  for variant in _VARIANTS.value:
    ms = [r[variant]["ms_median"] for r in rounds]
    row = {"ms_per_step": statistics.median(ms), "ms_rounds": ms,
           "peak_rss_mb": max(r[variant]["peak_rss_mb"] for r in rounds),
           "params_per_gaussian": rounds[0][variant]["params_per_gaussian"],
           "chunks_per_step": rounds[0][variant]["chunks_per_step"]}
    _, at, chunks_per_step = variant.partition("@")
    base = f"deterministic{at}{chunks_per_step}"  # the same loop step as `variant`
    if base in rounds[0]:
      row["ratio"] = statistics.median(r[variant]["ms_median"] / r[base]["ms_median"]
                                       for r in rounds)
    row["vs_first"] = statistics.median(r[variant]["ms_median"] / r[first_variant]["ms_median"]
                                        for r in rounds)
    table[variant] = row
  print(f"\n{'variant':>16} | {'ms/step':>8} | {'ratio':>6} | {'vs_first':>8} | "
        f"{'peak RSS MB':>11} | params/G")
  for variant, row in table.items():
    print(f"{variant:>16} | {row['ms_per_step']:8.1f} | {row.get('ratio', float('nan')):6.3f} | "
          f"{row['vs_first']:8.3f} | {row['peak_rss_mb']:11.0f} | {row['params_per_gaussian']}")
  first = rounds[0][first_variant]
  import jax  # After the children: only to name the device the figures were taken on.

  from mfsample._json import write_json
  machine = {"platform": platform.platform(), "cpu_count": os.cpu_count(),
             "jax": jax.__version__, "device": str(jax.devices()[0])}
  write_json(_OUT.value, {"machine": machine, "table": table, "rounds": rounds,
                          "resolution": first["resolution"],
                          "from_checkpoints": _FROM.value, "live_gaussians": first["live"],
                          "points": _POINTS.value, "samples": _SAMPLES.value,
                          "steps": _STEPS.value,
                          "load_end": _load()})
  print(f"saved {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
