"""Renderer benchmark: forward and forward+backward time, memory, scaling, and variants.

For every cell (N Gaussians x image size, SH degree 3, or gsplat's garden workload) and every
variant of the settings (each combination of --compositor, --radius_sigma, --chunks_per_step,
--chunk_size, --searchsorted and --skip_unused_steps), a fresh subprocess renders the scene,
fits the intersection budget, then times the jitted forward render and the jitted
forward+backward (gradients w.r.t. every Gaussian parameter and the camera) as the median of
repeated calls after warm-up (`mfsample._bench.time_render`). Peak memory is the
subprocess's peak resident set size (which includes the ~0.3 GB JAX runtime) and XLA's own
accounting of the compiled backward program (arguments + outputs + temporaries). Small cells
also time the dense reference renderer, in the first variant's process, as a ratio.

Variants run in interleaved rounds (--rounds): within a round every variant of a cell runs
back to back, and each variant's time is divided by the first variant's of the same cell and
round, so a change of the machine's load between rounds does not bias the ratios. Printed:
median times over rounds and the median of the per-round ratios.

The cell `garden` is gsplat's garden workload (`mfsample._workloads.garden`: --garden, or
its generated stand-in). --trace_dir writes a JAX profiler trace (TensorBoard / Perfetto) of
a few calls of each variant, for a per-kernel profile. A whole training step and the
renderer's share of it: `benchmarks/train_step.py --render_share`.

  python benchmarks/render.py --quick --radius_sigma=3.0,3.33      # the old and the new rule
  python benchmarks/render.py --quick --radius_sigma=3.0,3.33 --clock=process  # shared CPU
  python benchmarks/render.py --cells=50000x400 --compositor=jnp,pallas
  python benchmarks/render.py --cells=50000x400 --chunks_per_step=16,64,256,1024
  python benchmarks/render.py --cells=50000x400 --searchsorted=scan,sort,compare_all
  python benchmarks/render.py --cells=garden \
      --garden=PATH/test_garden.npz --repeats=3

On a CPU the pallas compositor runs in the Pallas interpreter: its times there are marked
"interpreted" and measure nothing about a GPU.
"""

import itertools
import json
import os
import statistics
import subprocess
import sys

from absl import app, flags

FULL_CELLS = [f"{n}x{r}" for n in (2000, 10000, 50000) for r in (100, 200, 400)]
QUICK_CELLS = ["2000x100", "10000x200"]
GARDEN_CELL = "garden"
DENSE_LIMIT = 2e7  # H * W * N: the dense reference holds [H W, N] arrays

_CELLS = flags.DEFINE_list("cells", None, "NxRES cells, or garden; default: the full 3x3 grid.")
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
_SKIP = flags.DEFINE_list("skip_unused_steps", ["True"],
                          "RenderSettings.skip_unused_steps values (True, False).")
_DENSE = flags.DEFINE_bool("dense", True, "Time the dense reference on small cells.")
_CLOCK = flags.DEFINE_enum(
    "clock", "wall", ["wall", "process"],
    "wall: elapsed time (latency). process: CPU time of the benchmark process, all its threads "
    "(the work done; steadier than wall time on a machine shared with other jobs, and not a "
    "latency; meaningless for a GPU, whose work is not the process's CPU time).")
_GARDEN = flags.DEFINE_string(
    "garden", "", "gsplat's test_garden.npz for the garden cell (default: its generated "
    "stand-in, `mfsample._workloads.garden`).")
_TRACE = flags.DEFINE_string("trace_dir", None, "Write a profiler trace per variant here.")
_OUT = flags.DEFINE_string("out", "workdirs/bench_render.json", "Where to save the JSON.")
_ONE = flags.DEFINE_string("one_cell", None, "Internal: run one cell and print its JSON.")
_VARIANT = flags.DEFINE_string("variant", None, "Internal: the variant's settings as JSON.")


def _variants():
  """Every combination of the listed settings, the first values first."""
  skip = [{"true": True, "false": False}[v.lower()] for v in _SKIP.value]
  combos = itertools.product(_COMPOSITOR.value, map(float, _RADIUS_SIGMA.value),
                             map(int, _CHUNKS_PER_STEP.value), map(int, _CHUNK_SIZE.value),
                             _SEARCHSORTED.value, skip)
  keys = ("compositor", "radius_sigma", "chunks_per_step", "chunk_size", "searchsorted_method",
          "skip_unused_steps")
  return [dict(zip(keys, c, strict=True)) for c in combos]


def _label(variant):
  return (f"{variant['compositor']} r={variant['radius_sigma']:g} "
          f"cps={variant['chunks_per_step']} chunk={variant['chunk_size']} "
          f"ss={variant['searchsorted_method']} skip={variant['skip_unused_steps']}")


def _trace(fn, name, trace_dir):
  """A profiler trace of three calls of `fn` under trace_dir/name."""
  import jax

  if not trace_dir:
    return
  with jax.profiler.trace(os.path.join(trace_dir, name.replace(" ", "_"))):
    for _ in range(3):
      jax.block_until_ready(fn())


def cell_workload(cell, garden=""):
  """The `Workload` of a cell: "NxRES" random Gaussians, or "garden"."""
  from mfsample import _workloads

  if cell == GARDEN_CELL:
    return _workloads.garden(garden)
  n, res = map(int, cell.split("x"))
  return _workloads.random_cell(n, res)


def run_cell(cell, repeats, variant, dense, *, clock="wall", garden="", trace_dir=None):
  """Measures one cell with one variant in this process; returns a dict."""
  import jax
  import jax.numpy as jnp

  from mfsample import RenderSettings
  from mfsample._bench import fitted_settings, loss_weights, median_ms, peak_rss_mb, time_render
  from mfsample.renderer.reference import render_reference
  from mfsample.renderer.render import render

  gaussians, camera, source = cell_workload(cell, garden)
  settings = fitted_settings(gaussians, camera, RenderSettings.holding(1, **variant))
  timing = time_render(gaussians, camera, settings, repeats=repeats, clock=clock)
  n = gaussians.num_gaussians
  result = {
      "cell": cell,
      "source": source,
      "variant": variant,
      "num_gaussians": n,
      "resolution": max(camera.width, camera.height),
      "image": [camera.width, camera.height],
      **timing.figures,
      # Before the dense reference runs: the tiled renderer's own peak.
      "peak_rss_mb": peak_rss_mb(),
  }
  if trace_dir:
    backward = jax.jit(jax.grad(lambda g: jnp.sum(render(g, camera, settings=settings).rgb)))
    _trace(lambda: backward(gaussians), f"{cell}_{_label(variant)}", trace_dir)
  if dense and n * camera.width * camera.height <= DENSE_LIMIT:
    weights = jnp.asarray(loss_weights(camera))
    dense_fwd = jax.jit(lambda g, c: render_reference(g, c, settings=settings)[0])

    def dense_loss(g, cam):
      return jnp.sum(weights * render_reference(g, cam, settings=settings)[0])

    dense_bwd = jax.jit(jax.value_and_grad(dense_loss, argnums=(0, 1)))
    result["dense_forward_ms"], _ = median_ms(lambda: dense_fwd(gaussians, camera), repeats,
                                              clock)
    result["dense_forward_backward_ms"], _ = median_ms(lambda: dense_bwd(gaussians, camera),
                                                       repeats, clock)
  return result


def _interpreted(row, machine):
  return row["variant"]["compositor"] == "pallas" and machine["backend"] == "cpu"


def _table(rows, machine):
  """Times per cell and variant (medians over rounds) and ratios to the cell's first."""
  lines = ["| cell | variant | intersections | fwd ms | fwd+bwd ms | fwd x first "
           "| fwd+bwd x first | peak RSS MB | dense fwd / fwd+bwd (x slower) |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
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
        f"| {fmt('forward_backward_ratio', '.3f')} | {fmt('peak_rss_mb', '.0f')} | {dense} |")
  return "\n".join(lines)


def _summarise(rounds, variants):
  """Per cell and variant: median times over rounds and median per-round ratios to the
  cell's first variant."""
  rows = []
  keys = ("forward_ms", "forward_backward_ms")
  for cell in dict.fromkeys(cell for cell, _ in rounds[0]):
    for v in range(len(variants)):
      runs = [rnd[(cell, v)] for rnd in rounds]
      row = dict(runs[0])
      for key in keys:
        if key in row:
          row[key] = statistics.median(run[key] for run in runs)
      for key, ratio_key in (("forward_ms", "forward_ratio"),
                             ("forward_backward_ms", "forward_backward_ratio")):
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
  from mfsample._bench import machine

  result = run_cell(_ONE.value, _REPEATS.value, json.loads(_VARIANT.value), _DENSE.value,
                    clock=_CLOCK.value, garden=_GARDEN.value, trace_dir=_TRACE.value)
  result["machine"] = machine()
  print("RESULT " + json.dumps(result))


def main(argv):
  del argv
  if _ONE.value:
    _child_main()
    return
  cells = _CELLS.value or (QUICK_CELLS if _QUICK.value else FULL_CELLS)
  variants = _variants()
  env = dict(os.environ, PYTHONPATH=os.pathsep.join([".", os.environ.get("PYTHONPATH", "")]))
  passthrough = [f"--repeats={_REPEATS.value}", f"--clock={_CLOCK.value}",
                 f"--garden={_GARDEN.value}"]
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
  fitted = [r for r in rows if r["variant"] == variants[0] and r["cell"] != GARDEN_CELL]
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
