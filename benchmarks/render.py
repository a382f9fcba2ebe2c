"""Renderer benchmark: forward and forward+backward time, peak memory, scaling.

For every cell (N Gaussians x image size, SH degree 3) a fresh subprocess renders a random
scene, fits the intersection budget, then times the jitted forward render and the jitted
forward+backward (gradients w.r.t. every Gaussian parameter and the camera) as the median
of repeated calls after warm-up. Peak memory is the subprocess's peak resident set size
(which includes the ~0.3 GB JAX runtime) and XLA's own accounting of the compiled
backward program (arguments + outputs + temporaries). Small cells also time the dense
reference renderer in the same process, as a ratio.

  python benchmarks/render.py                 # the full table (a few minutes)
  python benchmarks/render.py --quick         # two cells, for a smoke run
  python benchmarks/render.py --out results/render_gpu.json --cells 10000x800
  python benchmarks/render.py --cells=50000x400 --chunks_per_step=16,64,256  # loop length
"""

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

_CELLS = flags.DEFINE_list("cells", None, "NxRES cells; default: the full 3x3 grid.")
_QUICK = flags.DEFINE_bool("quick", False, "Only " + ", ".join(QUICK_CELLS) + ".")
_REPEATS = flags.DEFINE_integer("repeats", 7, "Timed calls per measurement (median).")
_CHUNKS_PER_STEP = flags.DEFINE_list(
    "chunks_per_step", ["16"], "RenderSettings.chunks_per_step of every cell; several values "
    "measure every cell at each (the compositing loop's work per sequential step).")
_OUT = flags.DEFINE_string("out", "results/bench_render.json", "Where to save the JSON.")
_ONE = flags.DEFINE_string("one_cell", None, "Internal: run one cell and print its JSON.")


def _median_ms(fn, repeats):
  import jax

  jax.block_until_ready(fn())  # warm-up (compilation happened before)
  times = []
  for _ in range(repeats):
    start = time.perf_counter()
    jax.block_until_ready(fn())
    times.append(time.perf_counter() - start)
  return 1e3 * statistics.median(times)


def run_cell(cell, repeats, chunks_per_step=16):
  """Measures one cell in this process; returns a dict."""
  import jax
  import jax.numpy as jnp

  from mfsample import RenderSettings, render
  from mfsample.renderer.budget import render_with_budget
  from mfsample.renderer.reference import render_reference
  from mfsample.testing import orbit_camera, random_gaussians

  n, res = map(int, cell.split("x"))
  gaussians = random_gaussians(n, sh_degree=3, seed=0, scale_range=(0.005, 0.05))
  camera = orbit_camera(res, res, distance=3.5, fov_x=0.9)
  target = jnp.asarray(jax.random.uniform(jax.random.PRNGKey(0), (res, res, 3)))

  # A start that holds 4096 intersections in whole loop steps; it grows on overflow.
  start = RenderSettings.holding(1 << 12, chunks_per_step=chunks_per_step)
  out, settings = render_with_budget(render, start, gaussians, camera)

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
      "chunks_per_step": chunks_per_step,
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
  if n * res * res <= DENSE_LIMIT:
    dense_fwd = jax.jit(lambda g, c: render_reference(g, c, settings=settings)[0])

    def dense_loss(g, cam):
      return jnp.mean(jnp.abs(render_reference(g, cam, settings=settings)[0] - target))

    dense_bwd = jax.jit(jax.value_and_grad(dense_loss, argnums=(0, 1)))
    result["dense_forward_ms"] = _median_ms(lambda: dense_fwd(gaussians, camera), repeats)
    result["dense_forward_backward_ms"] = _median_ms(lambda: dense_bwd(gaussians, camera),
                                                     repeats)
  return result


def _table(rows):
  lines = ["| N | image | chunks / step | intersections | fwd ms | fwd+bwd ms "
           "| ms / 1k isect (fwd+bwd) | peak RSS MB | XLA bwd MB "
           "| dense fwd / fwd+bwd (x slower) |",
           "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
  for r in rows:
    dense = "-"
    if "dense_forward_ms" in r:
      dense = (f"{r['dense_forward_ms'] / r['forward_ms']:.1f}x / "
               f"{r['dense_forward_backward_ms'] / r['forward_backward_ms']:.1f}x")
    xla = "-" if r["xla_backward_bytes"] is None else f"{r['xla_backward_bytes'] / 2**20:.0f}"
    lines.append(
        f"| {r['num_gaussians']} | {r['resolution']}^2 | {r.get('chunks_per_step', 16)} "
        f"| {r['intersections']} "
        f"| {r['forward_ms']:.1f} | {r['forward_backward_ms']:.1f} "
        f"| {1e3 * r['forward_backward_ms'] / max(r['intersections'], 1):.2f} "
        f"| {r['peak_rss_mb']:.0f} | {xla} | {dense} |")
  return "\n".join(lines)


def _linear_fit(rows, key):
  """Least-squares time = a + b * intersections, and its R^2."""
  import numpy as np

  x = np.array([r["intersections"] for r in rows], float)
  y = np.array([r[key] for r in rows], float)
  b, a = np.polyfit(x, y, 1)
  pred = a + b * x
  r2 = 1.0 - np.sum((y - pred) ** 2) / max(np.sum((y - y.mean()) ** 2), 1e-12)
  return {"intercept_ms": a, "ms_per_1k_intersections": 1e3 * b, "r2": r2}


def main(argv):
  del argv
  if _ONE.value:
    print("RESULT " + json.dumps(run_cell(_ONE.value, _REPEATS.value,
                                          int(_CHUNKS_PER_STEP.value[0]))))
    return
  cells = _CELLS.value or (QUICK_CELLS if _QUICK.value else FULL_CELLS)
  rows = []
  for cell in cells:
    for chunks_per_step in _CHUNKS_PER_STEP.value:
      print(f"[bench] {cell}, {chunks_per_step} chunks per step ...", flush=True)
      proc = subprocess.run(
          [sys.executable, __file__, f"--one_cell={cell}", f"--repeats={_REPEATS.value}",
           f"--chunks_per_step={chunks_per_step}"],
          capture_output=True, text=True, check=False)
      line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
      if proc.returncode or not line:
        print(proc.stdout[-2000:], proc.stderr[-4000:], file=sys.stderr)
        raise SystemExit(f"cell {cell} failed")
      rows.append(json.loads(line[0][len("RESULT "):]))
      print(_table(rows[-1:]).splitlines()[-1], flush=True)

  import jax

  summary = {
      "machine": {"platform": platform.platform(), "cpu_count": os.cpu_count(),
                  "jax": jax.__version__, "device": str(jax.devices()[0])},
      "cells": rows,
  }
  # Time against intersections at one loop setting (the first asked for).
  fitted = [r for r in rows if r["chunks_per_step"] == int(_CHUNKS_PER_STEP.value[0])]
  if len(fitted) >= 3:
    summary["fit_forward"] = _linear_fit(fitted, "forward_ms")
    summary["fit_forward_backward"] = _linear_fit(fitted, "forward_backward_ms")
  print()
  print(_table(rows))
  for key in ("fit_forward", "fit_forward_backward"):
    if key in summary:
      f = summary[key]
      print(f"{key}: time = {f['intercept_ms']:.1f} ms + {f['ms_per_1k_intersections']:.2f} ms"
            f" per 1k intersections (R^2 = {f['r2']:.3f})")
  from mfsample._json import write_json
  write_json(_OUT.value, summary)
  print(f"saved {_OUT.value}")
  if "fit_forward" in summary:
    _plot(summary, os.path.splitext(_OUT.value)[0] + ".png")


def _plot(summary, path):
  """Time against intersections, with the linear fits: the scaling claim as a picture."""
  try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
  except ImportError:
    print("matplotlib not installed: no plot")
    return
  import numpy as np

  first = summary["cells"][0]["chunks_per_step"]
  rows = [r for r in summary["cells"] if r["chunks_per_step"] == first]  # those fitted
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
