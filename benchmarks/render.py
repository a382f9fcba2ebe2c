"""Renderer benchmark: forward and forward+backward time, memory, scaling, and variants.

For every cell (N Gaussians x image size, SH degree 3) and every variant of the settings (each
combination of --compositor, --radius_sigma, --chunks_per_step, --chunk_size and
--searchsorted), a fresh subprocess renders a random scene, fits the intersection budget,
then times the jitted forward render and the jitted forward+backward (gradients w.r.t. every
Gaussian parameter and the camera) as the median of repeated calls after warm-up. Peak memory
is the subprocess's peak resident set size (which includes the ~0.3 GB JAX runtime) and XLA's
own accounting of the compiled backward program (arguments + outputs + temporaries). Small
cells also time the dense reference renderer, in the first variant's process, as a ratio.

Variants run in interleaved rounds (--rounds): within a round every variant of a cell runs
back to back, and each variant's time is divided by the first variant's of the same cell and
round, so a change of the machine's load between rounds does not bias the ratios. Printed:
median times over rounds and the median of the per-round ratios.

--step times a whole training step instead (lego, configs/train_lego.py, --step_points
initial points, --step_size pixels, densification off, the config's sampler) and, in the same
process, the renderer's forward+backward on that step's mean Gaussians and first training
camera: the share of the step spent outside the renderer. --trace_dir writes a JAX profiler
trace (TensorBoard / Perfetto) of a few calls of each variant, for a per-kernel profile.

  python benchmarks/render.py --quick --radius_sigma=3.0,3.33      # the old and the new rule
  python benchmarks/render.py --quick --radius_sigma=3.0,3.33 --clock=process  # shared CPU
  python benchmarks/render.py --cells=50000x400 --compositor=jnp,pallas
  python benchmarks/render.py --cells=50000x400 --chunks_per_step=16,64,256,1024
  python benchmarks/render.py --cells=50000x400 --searchsorted=scan,sort,compare_all
  python benchmarks/render.py --step --compositor=jnp,pallas --trace_dir=workdirs/trace

On a CPU the pallas compositor runs in the Pallas interpreter: its times there are marked
"interpreted" and measure nothing about a GPU.
"""

import itertools
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time

from absl import app, flags

FULL_CELLS = [f"{n}x{r}" for n in (2000, 10000, 50000) for r in (100, 200, 400)]
QUICK_CELLS = ["2000x100", "10000x200"]
DENSE_LIMIT = 2e7  # H * W * N: the dense reference holds [H W, N] arrays
STEP_CELL = "step"

_CELLS = flags.DEFINE_list("cells", None, "NxRES cells; default: the full 3x3 grid.")
_QUICK = flags.DEFINE_bool("quick", False, "Only " + ", ".join(QUICK_CELLS) + ".")
_REPEATS = flags.DEFINE_integer("repeats", 7, "Timed calls per measurement (median).")
_ROUNDS = flags.DEFINE_integer("rounds", 1, "Interleaved rounds over all variants.")
_COMPOSITOR = flags.DEFINE_list("compositor", ["jnp"], "RenderSettings.compositor values.")
_RADIUS_SIGMA = flags.DEFINE_list(
    "radius_sigma", ["3.33"], "RenderSettings.radius_sigma values (3.0: the former 3-sigma "
    "footprint; 3.33: the alpha rule for every opacity).")
_CHUNKS_PER_STEP = flags.DEFINE_list(
    "chunks_per_step", ["16"], "RenderSettings.chunks_per_step values (the jnp compositor's "
    "work per sequential loop step).")
_CHUNK_SIZE = flags.DEFINE_list("chunk_size", ["32"], "RenderSettings.chunk_size values.")
_SEARCHSORTED = flags.DEFINE_list("searchsorted", ["scan"],
                                  "RenderSettings.searchsorted_method values.")
_DENSE = flags.DEFINE_bool("dense", True, "Time the dense reference on small cells.")
_CLOCK = flags.DEFINE_enum(
    "clock", "wall", ["wall", "process"],
    "wall: elapsed time (latency). process: CPU time of the benchmark process, all its threads "
    "(the work done; steadier than wall time on a machine shared with other jobs, and not a "
    "latency; meaningless for a GPU, whose work is not the process's CPU time).")
_STEP = flags.DEFINE_bool("step", False, "Time a whole training step and its renderer.")
_STEP_SIZE = flags.DEFINE_integer("step_size", 400, "--step: image side (lego 800 / 2^k).")
_STEP_POINTS = flags.DEFINE_integer("step_points", 100_000, "--step: initial points.")
_DATA = flags.DEFINE_string("data", "data/nerf_synthetic/lego",
                            "--step: NeRF Synthetic lego folder (synthetic scene if absent).")
_TRACE = flags.DEFINE_string("trace_dir", None, "Write a profiler trace per variant here.")
_OUT = flags.DEFINE_string("out", "workdirs/bench_render.json", "Where to save the JSON.")
_ONE = flags.DEFINE_string("one_cell", None, "Internal: run one cell and print its JSON.")
_VARIANT = flags.DEFINE_string("variant", None, "Internal: the variant's settings as JSON.")


def _variants():
  """Every combination of the listed settings, the first values first."""
  combos = itertools.product(_COMPOSITOR.value, map(float, _RADIUS_SIGMA.value),
                             map(int, _CHUNKS_PER_STEP.value), map(int, _CHUNK_SIZE.value),
                             _SEARCHSORTED.value)
  keys = ("compositor", "radius_sigma", "chunks_per_step", "chunk_size", "searchsorted_method")
  return [dict(zip(keys, c, strict=True)) for c in combos]


def _label(variant):
  return (f"{variant['compositor']} r={variant['radius_sigma']:g} "
          f"cps={variant['chunks_per_step']} chunk={variant['chunk_size']} "
          f"ss={variant['searchsorted_method']}")


def _median_ms(fn, repeats):
  import jax

  clock = time.process_time if _CLOCK.value == "process" else time.perf_counter
  jax.block_until_ready(fn())  # warm-up (compilation happened before)
  times = []
  for _ in range(repeats):
    start = clock()
    jax.block_until_ready(fn())
    times.append(clock() - start)
  return 1e3 * statistics.median(times)


def _trace(fn, name):
  """A profiler trace of three calls of `fn` under --trace_dir/name."""
  import jax

  if not _TRACE.value:
    return
  with jax.profiler.trace(os.path.join(_TRACE.value, name.replace(" ", "_"))):
    for _ in range(3):
      jax.block_until_ready(fn())


def _start_settings(variant, budget=1 << 12):
  """Settings of `variant` holding `budget` intersections in whole loop steps."""
  from mfsample import RenderSettings

  return RenderSettings.holding(budget, **variant)


def _machine():
  import jax

  device = jax.devices()[0]
  return {"platform": platform.platform(), "cpu_count": os.cpu_count(), "jax": jax.__version__,
          "device": str(device), "device_kind": device.device_kind,
          "backend": jax.default_backend()}


def run_cell(cell, repeats, variant, dense):
  """Measures one cell with one variant in this process; returns a dict."""
  import jax
  import jax.numpy as jnp

  from mfsample import render
  from mfsample.renderer.budget import render_with_budget
  from mfsample.renderer.reference import render_reference
  from mfsample.testing import orbit_camera, random_gaussians

  n, res = map(int, cell.split("x"))
  gaussians = random_gaussians(n, sh_degree=3, seed=0, scale_range=(0.005, 0.05))
  camera = orbit_camera(res, res, distance=3.5, fov_x=0.9)
  target = jnp.asarray(jax.random.uniform(jax.random.PRNGKey(0), (res, res, 3)))
  out, settings = render_with_budget(render, _start_settings(variant), gaussians, camera)

  def loss(g, cam):
    return jnp.mean(jnp.abs(render(g, cam, settings=settings).rgb - target))

  forward = jax.jit(lambda g, c: render(g, c, settings=settings).rgb)
  backward = jax.jit(jax.value_and_grad(loss, argnums=(0, 1)))
  compiled_bwd = backward.lower(gaussians, camera).compile()
  mem = compiled_bwd.memory_analysis()
  xla_bytes = None
  if mem is not None:
    xla_bytes = (mem.argument_size_in_bytes + mem.output_size_in_bytes
                 + mem.temp_size_in_bytes)
  result = {
      "cell": cell,
      "variant": variant,
      "num_gaussians": n,
      "resolution": res,
      "budget": settings.max_intersections,
      "intersections": int(out.stats.num_intersections),
      "padded_intersections": int(out.stats.num_padded),
      "busiest_tile": int(out.stats.max_tile_load),
      "forward_ms": _median_ms(lambda: forward(gaussians, camera), repeats),
      "forward_backward_ms": _median_ms(lambda: compiled_bwd(gaussians, camera), repeats),
      "xla_backward_bytes": xla_bytes,
      # Before the dense reference runs: the tiled renderer's own peak.
      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
  }
  _trace(lambda: compiled_bwd(gaussians, camera), f"{cell}_{_label(variant)}")
  if dense and n * res * res <= DENSE_LIMIT:
    dense_fwd = jax.jit(lambda g, c: render_reference(g, c, settings=settings)[0])

    def dense_loss(g, cam):
      return jnp.mean(jnp.abs(render_reference(g, cam, settings=settings)[0] - target))

    dense_bwd = jax.jit(jax.value_and_grad(dense_loss, argnums=(0, 1)))
    result["dense_forward_ms"] = _median_ms(lambda: dense_fwd(gaussians, camera), repeats)
    result["dense_forward_backward_ms"] = _median_ms(lambda: dense_bwd(gaussians, camera),
                                                     repeats)
  return result


def run_step(repeats, variant):
  """A whole training step, and the renderer's share of it, in this process."""
  import dataclasses

  import jax
  import jax.numpy as jnp

  from configs import train_lego
  from mfsample import RenderSettings, render
  from mfsample.data import datasets as data_lib
  from mfsample.model import mean_gaussians
  from mfsample.renderer.budget import fit_budget, render_with_budget
  from mfsample.train import loop
  from mfsample.train.step import make_train_step

  config = train_lego.get_config()
  config.model.init_points = _STEP_POINTS.value
  config.data.path = _DATA.value
  config.data.downscale = max(800 // _STEP_SIZE.value, 1)
  config.densify.start = 10**9  # the jitted step alone
  config.train.progress = False
  if not os.path.isdir(config.data.path):
    config.data.kind = "synthetic"
    config.data.init_bounds = (-0.8, 0.8)
    syn = config.data.synthetic
    syn.num_gaussians, syn.width, syn.height = 2000, _STEP_SIZE.value, _STEP_SIZE.value
    syn.sh_degree, syn.num_train, syn.num_test = 3, 4, 1
  dataset = data_lib.load_dataset(config.data)
  views = data_lib.to_device(dataset.train)
  setup = loop.make_setup(config, dataset.train)
  state = loop.init_state(config, setup, dataset.bounds)
  base = setup.step_config.settings
  fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(base)
            if f.name != "max_intersections"}
  settings = RenderSettings.holding(base.max_intersections, **{**fields, **variant})

  def step_fn(settings):
    step_config = dataclasses.replace(setup.step_config, settings=settings)
    return make_train_step(step_config), step_config.num_samples

  fn, m = step_fn(settings)
  view = jnp.int32(0)

  def one_step():
    return fn(state, views.images, views.cameras, view, setup.sobol[:m])

  while True:  # grow the budget as the training loop does
    _, metrics = one_step()
    if not bool(metrics.overflow):
      break
    settings = fit_budget(settings, metrics)
    fn, m = step_fn(settings)
  gaussians = mean_gaussians(state.model)
  camera = jax.tree.map(lambda x: x[0], views.cameras)
  image = views.images[0]
  out, render_settings = render_with_budget(render, settings, gaussians, camera)

  def loss(g, cam):
    return jnp.mean(jnp.abs(render(g, cam, settings=render_settings).rgb - image))

  # allow_int: the live mask is a leaf of the Gaussians (its cotangent is float0).
  backward = jax.jit(jax.value_and_grad(loss, argnums=(0, 1), allow_int=True))
  step_ms = _median_ms(one_step, repeats)
  render_ms = _median_ms(lambda: backward(gaussians, camera), repeats)
  _trace(one_step, f"step_{_label(variant)}")
  return {
      "cell": STEP_CELL,
      "variant": variant,
      "num_gaussians": int(state.model.capacity),
      "resolution": int(views.images.shape[1]),
      "samples_per_step": int(m),
      "budget": settings.max_intersections,
      "intersections": int(out.stats.num_intersections),
      "step_ms": step_ms,
      "forward_backward_ms": render_ms,
      # The step renders its M samples forward and backward; the rest is outside.
      "outside_renderer_share": 1.0 - m * render_ms / step_ms,
      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
  }


def _interpreted(row, machine):
  return row["variant"]["compositor"] == "pallas" and machine["backend"] == "cpu"


def _table(rows, machine):
  """Times per cell and variant (medians over rounds) and ratios to the cell's first."""
  lines = ["| cell | variant | intersections | fwd ms | fwd+bwd ms | fwd x first "
           "| fwd+bwd x first | step ms | outside renderer | peak RSS MB "
           "| dense fwd / fwd+bwd (x slower) |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
  for r in rows:
    def fmt(key, spec=".1f", r=r):
      return format(r[key], spec) if r.get(key) is not None else "-"

    dense = "-"
    if "dense_forward_ms" in r:
      dense = (f"{r['dense_forward_ms'] / r['forward_ms']:.1f}x / "
               f"{r['dense_forward_backward_ms'] / r['forward_backward_ms']:.1f}x")
    label = _label(r["variant"]) + (" (interpreted)" if _interpreted(r, machine) else "")
    lines.append(
        f"| {r['cell']} | {label} | {r['intersections']} | {fmt('forward_ms')} "
        f"| {fmt('forward_backward_ms')} | {fmt('forward_ratio', '.3f')} "
        f"| {fmt('forward_backward_ratio', '.3f')} | {fmt('step_ms')} "
        f"| {fmt('outside_renderer_share', '.0%')} | {fmt('peak_rss_mb', '.0f')} | {dense} |")
  return "\n".join(lines)


def _summarise(rounds, variants):
  """Per cell and variant: median times over rounds and median per-round ratios to the
  cell's first variant."""
  rows = []
  keys = ("forward_ms", "forward_backward_ms", "step_ms")
  for cell in dict.fromkeys(cell for cell, _ in rounds[0]):
    for v in range(len(variants)):
      runs = [rnd[(cell, v)] for rnd in rounds]
      row = dict(runs[0])
      for key in keys:
        if key in row:
          row[key] = statistics.median(run[key] for run in runs)
      for key, ratio_key in (("forward_ms", "forward_ratio"),
                             ("forward_backward_ms", "forward_backward_ratio"),
                             ("step_ms", "step_ratio")):
        if key in row:
          row[ratio_key] = statistics.median(rnd[(cell, v)][key] / rnd[(cell, 0)][key]
                                             for rnd in rounds)
      row["rounds"] = runs
      rows.append(row)
  return rows


def _linear_fit(rows, key):
  """Least-squares time = a + b * intersections, and its R^2."""
  import numpy as np

  x = np.array([r["intersections"] for r in rows], float)
  y = np.array([r[key] for r in rows], float)
  b, a = np.polyfit(x, y, 1)
  pred = a + b * x
  r2 = 1.0 - np.sum((y - pred) ** 2) / max(np.sum((y - y.mean()) ** 2), 1e-12)
  return {"intercept_ms": a, "ms_per_1k_intersections": 1e3 * b, "r2": r2}


def _child_main():
  variant = json.loads(_VARIANT.value)
  if _ONE.value == STEP_CELL:
    result = run_step(_REPEATS.value, variant)
  else:
    result = run_cell(_ONE.value, _REPEATS.value, variant, _DENSE.value)
  result["machine"] = _machine()
  print("RESULT " + json.dumps(result))


def main(argv):
  del argv
  if _ONE.value:
    _child_main()
    return
  cells = ([STEP_CELL] if _STEP.value
           else _CELLS.value or (QUICK_CELLS if _QUICK.value else FULL_CELLS))
  variants = _variants()
  env = dict(os.environ, PYTHONPATH=os.pathsep.join([".", os.environ.get("PYTHONPATH", "")]))
  passthrough = [f"--repeats={_REPEATS.value}", f"--clock={_CLOCK.value}",
                 f"--step_size={_STEP_SIZE.value}",
                 f"--step_points={_STEP_POINTS.value}", f"--data={_DATA.value}"]
  if _TRACE.value:
    passthrough.append(f"--trace_dir={_TRACE.value}")
  rounds, machine = [], None
  for r in range(_ROUNDS.value):
    results = {}
    for cell in cells:
      for v, variant in enumerate(variants):
        print(f"[bench] round {r + 1}/{_ROUNDS.value}, {cell}, {_label(variant)} ...",
              flush=True)
        dense = _DENSE.value and r == 0 and v == 0
        proc = subprocess.run(
            [sys.executable, __file__, f"--one_cell={cell}", f"--variant={json.dumps(variant)}",
             f"--dense={dense}", *passthrough],
            capture_output=True, text=True, check=False, env=env)
        line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
        if proc.returncode or not line:
          print(proc.stdout[-2000:], proc.stderr[-4000:], file=sys.stderr)
          raise SystemExit(f"cell {cell} ({_label(variant)}) failed")
        res = json.loads(line[0][len("RESULT "):])
        machine = res.pop("machine")
        res["load_before"] = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
        results[(cell, v)] = res
    rounds.append(results)

  rows = _summarise(rounds, variants)
  summary = {"machine": machine, "variants": variants, "rounds": _ROUNDS.value,
             "clock": _CLOCK.value, "cells": rows}
  # Time against intersections for the first variant, over the cells.
  fitted = [r for r in rows if r["variant"] == variants[0] and r["cell"] != STEP_CELL]
  if len(fitted) >= 3:
    summary["fit_forward"] = _linear_fit(fitted, "forward_ms")
    summary["fit_forward_backward"] = _linear_fit(fitted, "forward_backward_ms")
  print()
  print(f"{machine['device_kind']} ({machine['backend']}), jax {machine['jax']}; "
        f"{_CLOCK.value} clock; {_ROUNDS.value} round(s); 'x first': time / the cell's first "
        "variant's time, median of the per-round ratios")
  print(_table(rows, machine))
  for key in ("fit_forward", "fit_forward_backward"):
    if key in summary:
      f = summary[key]
      print(f"{key}: time = {f['intercept_ms']:.1f} ms + {f['ms_per_1k_intersections']:.2f} ms"
            f" per 1k intersections (R^2 = {f['r2']:.3f})")
  from mfsample._json import write_json
  write_json(_OUT.value, summary)
  print(f"saved {_OUT.value}")
  if "fit_forward" in summary:
    _plot(summary, fitted, os.path.splitext(_OUT.value)[0] + ".png")


def _plot(summary, rows, path):
  """Time against intersections, with the linear fits: the scaling claim as a picture."""
  try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
  except ImportError:
    print("matplotlib not installed: no plot")
    return
  import numpy as np

  x = np.array([r["intersections"] for r in rows], float)
  fig, ax = plt.subplots(figsize=(6, 4))
  for key, fit_key, label in (("forward_ms", "fit_forward", "forward"),
                              ("forward_backward_ms", "fit_forward_backward",
                               "forward + backward")):
    y = np.array([r[key] for r in rows])
    (line,) = ax.plot(x / 1e3, y, "o", label=label)
    fit = summary[fit_key]
    xs = np.linspace(0, x.max(), 50)
    ax.plot(xs / 1e3, fit["intercept_ms"] + fit["ms_per_1k_intersections"] * xs / 1e3, "-",
            color=line.get_color(), alpha=0.6,
            label=f"fit: {fit['ms_per_1k_intersections']:.2f} ms / 1k, R2 {fit['r2']:.3f}")
  for r in rows:
    ax.annotate(f"{r['num_gaussians'] // 1000}k@{r['resolution']}",
                (r["intersections"] / 1e3, r["forward_backward_ms"]), fontsize=7,
                textcoords="offset points", xytext=(3, 3))
  ax.set_xlabel("tile intersections (thousands)")
  ax.set_ylabel("milliseconds (median)")
  ax.set_title(f"render time vs intersections ({summary['machine']['device']})")
  ax.legend(fontsize=8)
  fig.tight_layout()
  fig.savefig(path, dpi=120)
  print(f"saved {path}")


if __name__ == "__main__":
  sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
  app.run(main)
