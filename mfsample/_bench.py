"""Pieces shared by the scripts in `benchmarks/`: the machine record, the data hint, and the
timing of renders.

Every benchmark JSON carries `machine()`, so the table built from it can state the hardware
and the JAX version it was measured with.

Timing. `median_ms` blocks on each call's whole output (`jax.block_until_ready`) and reads
nothing else from the device inside the timed region, so a call's time is its dispatch plus
its device work. `pipelined_ms` queues calls without waiting and blocks once at the end:
where it is much below `median_ms`, per-call host work (dispatch, or synchronisations inside
the program) is a large part of the latency.
"""

import functools
import os
import platform
import resource
import statistics
import sys
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample.renderer.budget import fit_budget, render_with_budget
from mfsample.renderer.render import render

CLOCKS = {"wall": time.perf_counter, "process": time.process_time}

NERF_SYNTHETIC_HINT = (
    "NeRF Synthetic is linked from the NeRF project page "
    "(https://www.matthewtancik.com/nerf): download nerf_synthetic.zip from its Google Drive "
    "folder, unzip it, and point {flag} at the lego folder (default: "
    "data/nerf_synthetic/lego, relative to the working directory).")


def machine():
  """{platform, processor, cpu_count, backend, device_kind, device_count, jax}.

  Initialises JAX's backend: a caller that must not hold the accelerator (a parent whose
  children measure) calls it after them.
  """

  device = jax.devices()[0]
  return {"platform": platform.platform(), "processor": platform.machine(),
          "cpu_count": os.cpu_count(), "backend": jax.default_backend(),
          "device_kind": device.device_kind, "device_count": jax.device_count(),
          "jax": jax.__version__}


def require_scene_folder(path, flag):
  """Raises FileNotFoundError naming `flag`, `path` and where to get NeRF Synthetic when
  `path` holds no `transforms_train.json`."""
  if not os.path.isfile(os.path.join(path, "transforms_train.json")):
    raise FileNotFoundError(f"no NeRF Synthetic scene at {flag}={path!r} (no "
                            f"transforms_train.json there). "
                            + NERF_SYNTHETIC_HINT.format(flag=flag))


def load_average():
  """(1, 5, 15)-minute load averages, NaN where the platform has none."""
  try:
    return os.getloadavg()
  except OSError:
    return (float("nan"),) * 3


def peak_rss_mb():
  """This process's peak resident set size so far, in MB."""
  peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
  return peak / (2**20 if sys.platform == "darwin" else 1024.0)  # bytes on macOS, KiB on Linux


def device_memory_mb():
  """(peak, limit) MB of the default device's allocator so far; (None, None) where the
  backend keeps no such record (the CPU)."""
  stats = jax.devices()[0].memory_stats() or {}
  mb = lambda key: stats[key] / 2**20 if key in stats else None
  return mb("peak_bytes_in_use"), mb("bytes_limit")


def median_ms(fn, repeats, clock="wall"):
  """(median milliseconds of `repeats` calls of `fn` after one untimed call, the last
  output). Each call is timed until its whole output is ready.

  clock: "wall" (latency) or "process" (CPU time of this process, all threads: the work done
  on a CPU shared with other jobs; meaningless for a GPU).
  """
  timer = CLOCKS[clock]
  out = jax.block_until_ready(fn())
  times = []
  for _ in range(repeats):
    start = timer()
    out = jax.block_until_ready(fn())
    times.append(timer() - start)
  return 1e3 * statistics.median(times), out


def pipelined_ms(fn, repeats):
  """Wall milliseconds per call of `repeats` calls issued back to back, blocking on the last
  only (JAX dispatches asynchronously): the device's throughput when the host keeps up."""
  jax.block_until_ready(fn())
  start = time.perf_counter()
  outs = [fn() for _ in range(repeats)]
  jax.block_until_ready(outs)
  return 1e3 * (time.perf_counter() - start) / repeats


@functools.partial(jax.jit, static_argnames=("settings",))
def _tile_stats(gaussians, camera, *, settings):
  return render(gaussians, camera, settings=settings).stats


def fitted_settings(gaussians, camera, settings):
  """`settings` with the budget that training would grow to for this render (the next power
  of two of the padded intersection count, `mfsample.renderer.fit_budget`).

  The count comes from a jitted render that returns only its tile statistics: XLA drops the
  unused compositing, so finding the budget costs a projection and a sort per try, not a
  compilation of the whole renderer per power of two.
  """
  stats, fitted = render_with_budget(_tile_stats, settings.holding_budget(1), gaussians,
                                     camera, stats_of=lambda s: s, max_budget=1 << 30)
  # An overflowing try reports an upper bound of the need; the last one the exact count.
  return fit_budget(fitted, stats, allow_shrink=True)


class RenderTiming(NamedTuple):
  """What `time_render` measured and the outputs it timed (on the device)."""

  figures: dict  # forward_ms, forward_backward_ms, intersections, ... (JSON-ready)
  rgb: object  # [H, W, C]
  alpha: object  # [H, W]
  grads: tuple  # (d loss / d gaussians, d loss / d camera)


def loss_weights(camera, channels=3, seed=0):
  """[H, W, C] fixed N(0, 1) weights of `time_render`'s loss, the same on every device."""
  rng = np.random.default_rng(seed)
  return rng.normal(size=(camera.height, camera.width, channels)).astype(np.float32)


def _weighted_loss(gaussians, camera, weights, settings):
  rgb = render(gaussians, camera, settings=settings).rgb
  return jnp.sum(weights * rgb) / (camera.width * camera.height)


# allow_int: a live mask is a leaf of the Gaussians (its cotangent is float0).
_loss_and_grads = jax.jit(jax.value_and_grad(_weighted_loss, argnums=(0, 1), allow_int=True),
                          static_argnames=("settings",))


def time_render(gaussians, camera, settings, *, repeats, clock="wall", pipelined=False):
  """Times the jitted render of `gaussians` into `camera` and its forward+backward.

  Forward: `render(...)` (every output). Forward+backward: the value and the gradients
  w.r.t. the Gaussians and the camera of the loss sum(w * rgb) / (H W), w = `loss_weights`:
  linear in the image, so its gradients do not depend on the image and the gradients of two
  devices compare directly. Both are timed by `median_ms`; the compiled programs are shared
  by calls with equal settings and shapes.

  Returns:
    `RenderTiming`; figures: forward_ms, forward_backward_ms (and, with `pipelined`,
    forward_backward_pipelined_ms), intersections, padded_intersections, busiest_tile,
    overflow, budget, xla_backward_mb (XLA's arguments + outputs + temporaries of the
    compiled forward+backward; None where the backend does not say).
  """
  weights = jnp.asarray(loss_weights(camera))
  memory = _loss_and_grads.lower(gaussians, camera, weights,
                                 settings=settings).compile().memory_analysis()
  forward_ms, out = median_ms(lambda: render(gaussians, camera, settings=settings), repeats,
                              clock)
  backward = lambda: _loss_and_grads(gaussians, camera, weights, settings=settings)
  backward_ms, (_, grads) = median_ms(backward, repeats, clock)
  figures = {
      "forward_ms": forward_ms,
      "forward_backward_ms": backward_ms,
      "intersections": int(out.stats.num_intersections),
      "padded_intersections": int(out.stats.num_padded),
      "busiest_tile": int(out.stats.max_tile_load),
      "overflow": bool(out.stats.overflow),
      "budget": settings.max_intersections,
      "xla_backward_mb": None if memory is None else (
          memory.argument_size_in_bytes + memory.output_size_in_bytes
          + memory.temp_size_in_bytes) / 2**20,
  }
  if pipelined:
    figures["forward_backward_pipelined_ms"] = pipelined_ms(backward, repeats)
  return RenderTiming(figures, out.rgb, out.alpha, grads)
