"""Milliseconds per training step of every sampler on one scene, and peak memory.

Every variant starts from the same initial state (NeRF Synthetic lego at --size with the
lego config's random initial cloud, or a synthetic scene when --data holds no lego),
compiles the step, runs `--warmup` steps, then times `--steps` steps (median). Variants
run in interleaved rounds and each ratio to deterministic is taken within a round, so a
change in the machine's load between rounds does not bias the ratios. Densification is
off: this measures the jitted step (paper Tab. 4 measures the same thing per iteration).

Each measurement runs in a fresh subprocess, so its peak RSS is its own and no compilation
cache leaks between variants; `measure_variant` is the same measurement in this process.

  python benchmarks/train_step.py --rounds=3
  python benchmarks/train_step.py --clock=process  # on a CPU shared with others

A variant `NAME@C` composites C chunks per loop step (`render.chunks_per_step`, a speed
knob) and takes its ratio to `deterministic@C`; every variant also gets its ratio to the
first one listed (`vs_first`, within a round), which compares the C of a sweep. On a GPU,
where small steps are bound by launch latency, sweep it at the paper's scale:

  python benchmarks/train_step.py --size=400 --points=100000 --rounds=1 \
      --variants=deterministic@16,deterministic@64,deterministic@256,deterministic@1024

--compositor selects the renderer's compositor for every variant. --render_share also times
the renderer's forward+backward alone (on the step's mean Gaussians, the first training
camera, the same settings) and reports the share of the step spent outside it,
1 - M * render / step: the loss, SSIM, sampling and the optimiser. --fit_start_budget sizes
the first step's intersection budget from that render, so that a step that would overflow
the configured start budget is not compiled twice.

  PYTHONPATH=. python benchmarks/train_step.py --size=400 --points=100000 --samples=1 \
      --variants=rank2 --rounds=1 --compositor=pallas --render_share --fit_start_budget
"""

import copy
import json
import os
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
_COMPOSITOR = flags.DEFINE_enum("compositor", None, ["jnp", "pallas"],
                                "render.compositor of every variant (default: the config's).")
_RENDER_SHARE = flags.DEFINE_bool(
    "render_share", False, "Also time the renderer alone and report the step's share outside.")
_FIT_START_BUDGET = flags.DEFINE_bool(
    "fit_start_budget", False, "Size the first step's budget from a render of the start model.")
_OUT = flags.DEFINE_string("out", "workdirs/benchmarks/train_step.json", "Output JSON.")
_CHILD = flags.DEFINE_string("child", None, "Internal: run one variant and print JSON.")


def base_config(data, size, points, samples):
  """(training config, scene name) every variant starts from.

  The lego config at `size` x `size` (downscale 400 / size) with `points` initial points
  and M = `samples`; when `data` holds no NeRF Synthetic scene, the same at `size` on a
  synthetic scene of 2000 random Gaussians seen by 16 views (scene name "synthetic").
  """
  from mfsample.train.config import get_config

  config = get_config("lego")
  config.sampler.num_samples = samples
  config.model.init_points = points
  config.data.path = data
  config.data.downscale = max(400 // size, 1)
  if os.path.isfile(os.path.join(data, "transforms_train.json")):
    return config, "lego"
  config.data.kind = "synthetic"
  config.data.init_bounds = (-0.8, 0.8)
  config.data.width = config.data.height = size
  config.data.num_train, config.data.num_test = 16, 1
  syn = config.data.synthetic
  syn.num_gaussians, syn.sh_degree = 2000, 3
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
  import jax.numpy as jnp
  import numpy as np

  from mfsample.model import Model, Params, init_b_hat
  from mfsample.train import checkpoint as ckpt
  from mfsample.train import loop

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
  spec = fresh.model.spec
  b_hat, signs = init_b_hat(np.random.default_rng(0), live, shapes, spec, setup.init_scales)

  def pad(x):
    return jnp.asarray(np.concatenate([x, np.zeros((capacity - live,) + x.shape[1:], x.dtype)]))

  model = Model(Params(mean, {g: pad(v) for g, v in b_hat.items()}),
                {g: pad(v) for g, v in signs.items()}, jnp.asarray(mask),
                jnp.asarray(int(arrays[".model.sh_degree"]), jnp.int32), spec)
  return loop.init_state(model, setup)


def measure_variant(config, *, steps, warmup, from_checkpoints=None, clock="wall",
                    render_share=False, fit_start_budget=False):
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
    render_share: also time the renderer's forward+backward alone on the final state's mean
      Gaussians from the first training camera (`mfsample._bench.time_render`, the step's
      settings with the budget that render needs) and report the share of the step outside
      the renderer, 1 - M * render_forward_backward_ms / ms_median (an estimate: the step
      renders M samples of the model, not its mean).
    fit_start_budget: start with the budget the start model's mean needs from the first
      training camera (when above the configured one), so that the first step does not
      compile at a budget that overflows.

  Returns:
    {ms_median, ms_min, ms_all [steps], peak_rss_mb (of this process so far: a variant's
    own only in a fresh process), device_peak_mb (the device allocator's peak so far; None
    on a CPU), seconds_total, capacity, live, budget, chunks_per_step,
    compositor, params_per_gaussian (floats trained per Gaussian: mean and B_hat),
    resolution, samples}; with `render_share` also render_forward_backward_ms,
    render_intersections and outside_renderer_share.
  """
  import jax
  import numpy as np

  from mfsample._bench import device_memory_mb, fitted_settings, peak_rss_mb, time_render
  from mfsample.config_blocks import data_spec
  from mfsample.data import datasets as data_lib
  from mfsample.model import mean_gaussians
  from mfsample.renderer.budget import fit_budget
  from mfsample.train import loop
  from mfsample.train.config import recipe
  from mfsample.train.step import make_train_step

  dataset = data_lib.load_dataset(data_spec(config.data))
  views = data_lib.to_device(dataset.train)
  seed, num_views = int(config.seed), len(dataset.train)
  extent = config.data.extent
  if extent is None:  # 3DGS's, from the training cameras (as the training job)
    extent = data_lib.scene_extent(dataset.train.cameras)
  plan = recipe(config, extent=extent)
  model = plan.initial_model(seed=seed, bounds=dataset.bounds, points=dataset.points)
  setup = loop.make_setup(plan.settings, model, seed=seed, extent=extent, num_views=num_views)
  state = loop.init_state(model, setup)
  if from_checkpoints:
    state = _from_trained(state, setup, from_checkpoints)
  m = setup.step_config.num_samples
  first_camera = jax.tree.map(lambda x: x[0], views.cameras)
  if fit_start_budget:
    fitted = fitted_settings(mean_gaussians(state.model), first_camera,
                             setup.step_config.settings)
    if fitted.max_intersections > setup.step_config.settings.max_intersections:
      setup = setup.with_settings(fitted)
  fn = make_train_step(setup.step_config)
  timer = time.process_time if clock == "process" else time.perf_counter
  t0 = time.perf_counter()
  step, times = 0, []
  while step < warmup + steps:
    index, rows = loop.step_targets(setup, step, num_views)
    t = timer()
    new_state, metrics = fn(state, (views.images, views.cameras), index, rows)
    jax.block_until_ready(new_state)
    dt = timer() - t
    if bool(metrics.overflow):
      setup = setup.with_settings(fit_budget(setup.step_config.settings, metrics))
      fn = make_train_step(setup.step_config)
      continue
    state = new_state
    if step >= warmup:
      times.append(dt)
    step += 1
  settings = setup.step_config.settings
  result = {
      "ms_median": 1e3 * statistics.median(times), "ms_min": 1e3 * min(times),
      "ms_all": [1e3 * t for t in times], "peak_rss_mb": peak_rss_mb(),
      "seconds_total": time.perf_counter() - t0,
      "capacity": int(state.model.capacity), "live": int(np.sum(np.asarray(state.model.mask))),
      "budget": settings.max_intersections, "chunks_per_step": settings.chunks_per_step,
      "compositor": settings.compositor,
      "params_per_gaussian": int(sum(np.prod(x.shape[1:]) for x in
                                     jax.tree.leaves(state.model.params))),
      "resolution": int(views.images.shape[1]), "samples": int(m),
      "device_peak_mb": device_memory_mb()[0],
  }
  if render_share:
    gaussians = mean_gaussians(state.model)
    timing = time_render(gaussians, first_camera,
                         fitted_settings(gaussians, first_camera, settings),
                         repeats=steps, clock=clock)
    render_ms = timing.figures["forward_backward_ms"]
    result.update(render_forward_backward_ms=render_ms,
                  render_intersections=timing.figures["intersections"],
                  outside_renderer_share=1.0 - m * render_ms / result["ms_median"])
  return result


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
  measured, ratio (the same, against it); outside_renderer_share (median over rounds) where
  measured.
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
    if "outside_renderer_share" in rounds[0][variant]:
      row["outside_renderer_share"] = statistics.median(
          r[variant]["outside_renderer_share"] for r in rounds)
    table[variant] = row
  return table


def _child_flags():
  """The flags a child needs to rebuild this run's configs."""
  args = [f"--steps={_STEPS.value}", f"--warmup={_WARMUP.value}", f"--size={_SIZE.value}",
          f"--points={_POINTS.value}", f"--samples={_SAMPLES.value}", f"--data={_DATA.value}",
          f"--clock={_CLOCK.value}"]
  if _FROM.value:
    args.append(f"--from_checkpoints={_FROM.value}")
  if _COMPOSITOR.value:
    args.append(f"--compositor={_COMPOSITOR.value}")
  args += [f"--render_share={_RENDER_SHARE.value}",
           f"--fit_start_budget={_FIT_START_BUDGET.value}"]
  return args


def _measure_in_subprocess(variant):
  env = dict(os.environ, PYTHONPATH=os.pathsep.join([".", os.environ.get("PYTHONPATH", "")]))
  out = subprocess.run([sys.executable, __file__, f"--child={variant}", *_child_flags()],
                       env=env, capture_output=True, text=True, check=False)
  if out.returncode:
    raise RuntimeError(f"{variant} failed:\n{out.stderr[-3000:]}")
  return json.loads(out.stdout.strip().splitlines()[-1])


def _measure_here(variant):
  base, scene = base_config(_DATA.value, _SIZE.value, _POINTS.value, _SAMPLES.value)
  config = variant_config(base, variant)
  if _COMPOSITOR.value:
    config.render.compositor = _COMPOSITOR.value
  result = measure_variant(config, steps=_STEPS.value, warmup=_WARMUP.value,
                           from_checkpoints=_FROM.value, clock=_CLOCK.value,
                           render_share=_RENDER_SHARE.value,
                           fit_start_budget=_FIT_START_BUDGET.value)
  return dict(result, scene=scene)


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
        f"{'peak RSS MB':>11} | params/G | outside renderer")
  for variant, row in table.items():
    share = row.get("outside_renderer_share")
    print(f"{variant:>16} | {row['ms_per_step']:8.1f} | {row.get('ratio', float('nan')):6.3f} | "
          f"{row['vs_first']:8.3f} | {row['peak_rss_mb']:11.0f} | {row['params_per_gaussian']:8} | "
          + ("-" if share is None else f"{share:.0%}"))
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
  sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
  app.run(main)
