"""Throughput of candidate scoring and of data-parallel training steps on 1, 2, 4 devices.

One process, one model (a rank-2 field of `--points` random Gaussians on the tiny synthetic
scene), one set of candidates, one batch of training views; only the number of devices the
work is split over changes (`mfsample.sharding`: the first n devices). On a
CPU the devices are host devices (`--host_devices`, set before JAX starts: XLA's
`--xla_force_host_platform_device_count`), threads of one process sharing the machine's
cores; on a GPU machine, its GPUs. Every variant is compiled first; then the timed calls
alternate between the variants, one call of each per round, for `--rounds` rounds. Each
speed-up is the ratio to one device within a round, and the median over rounds is reported,
so a slow spell of a shared machine lands on every variant alike. Wall-clock and CPU time
(every thread of the process) are both recorded: the wall-clock gives the speed-up, the CPU
time the total work (what splitting costs on top).

  python benchmarks/scaling.py
  python benchmarks/scaling.py --devices=1,2,4,8 --host_devices=8 --rounds=9
"""

import os
import statistics
import sys
import time

from absl import app, flags

_HOST = flags.DEFINE_integer("host_devices", 4, "Host (CPU) devices to create; GPUs are as "
                             "they are.")
_DEVICES = flags.DEFINE_list("devices", ["1", "2", "4"], "Device counts to compare.")
_RES = flags.DEFINE_integer("resolution", 64, "Square image size of candidates and views.")
_CANDS = flags.DEFINE_integer("num_candidates", 32, "Candidates scored per timed call.")
_M = flags.DEFINE_integer("samples", 2, "M, samples of U.")
_BATCH = flags.DEFINE_integer("batch_size", 4, "Views per training step (train.batch_size).")
_POINTS = flags.DEFINE_integer("points", 2000, "Random Gaussians of the model (a rank-2 "
                               "field at its first step) scored and trained.")
_ROUNDS = flags.DEFINE_integer("rounds", 5, "Timed rounds, one call of each variant each.")
_OUT = flags.DEFINE_string("out", "workdirs/benchmarks/scaling.json", "JSON output.")


def alternate(fns, rounds):
  """{name: [(wall seconds, CPU seconds) per round]} of every fn of `fns` ({name: fn()}),
  each compiled and warmed up first, then called in turn, one call of each per round."""
  import jax

  for fn in fns.values():
    jax.block_until_ready(fn())
  times = {name: [] for name in fns}
  for _ in range(rounds):
    for name, fn in fns.items():
      w0, c0 = time.perf_counter(), time.process_time()
      jax.block_until_ready(fn())
      times[name].append((time.perf_counter() - w0, time.process_time() - c0))
  return times


def summarize(times, items):
  """{n: figures} from `alternate`'s times of variants keyed by device count n, `items`
  (candidates, views) processed per call: median wall and CPU seconds per call, items per
  second, and the speed-up over the smallest n (the median over rounds of the ratio within
  a round)."""
  base = min(times)
  out = {}
  for n, rows in times.items():
    walls, cpus = [w for w, _ in rows], [c for _, c in rows]
    out[n] = {"wall_seconds": statistics.median(walls), "cpu_seconds": statistics.median(cpus),
              "per_second": items / statistics.median(walls),
              "speedup": statistics.median(b[0] / w for b, w in zip(times[base], walls,
                                                                   strict=True)),
              "cpu_ratio": statistics.median(c / b[1] for b, c in zip(times[base], cpus,
                                                                     strict=True)),
              "wall_rounds": walls, "cpu_rounds": cpus}
  return out


def setup_run(*, batch_size, resolution, points):
  """(views, setup, state) of a rank-2 field of `points` random Gaussians at its first step,
  trained with `batch_size` views per step on the tiny synthetic scene (random Gaussians seen
  by max(12, `batch_size`) orbit views at `resolution`, on black:
  `mfsample.testing.synthetic_views`)."""
  import jax
  import numpy as np

  from mfsample import testing
  from mfsample.data.datasets import scene_extent
  from mfsample.groups import GROUPS
  from mfsample.model import init_model
  from mfsample.renderer import RenderSettings
  from mfsample.samplers import SamplerSpec
  from mfsample.train import TrainSettings, loop

  background = (0.0, 0.0, 0.0)
  views, _ = testing.synthetic_views(max(12, batch_size), size=resolution,
                                     background=background)
  extent = scene_extent(views.cameras)
  settings = TrainSettings(batch_size=batch_size, background=background,
                           render=RenderSettings(max_intersections=1 << 12))
  # Uniform in the scene box (the ground truth's cube + 0.2), as a run without SfM starts.
  xyz = np.random.default_rng(0).uniform(-0.8, 0.8, (points, 3))
  model = init_model(jax.random.PRNGKey(0), xyz, spec=SamplerSpec.default(GROUPS, extent=extent),
                     sh_degree=0, init_scales=settings.b_hat_init_scales(extent))
  setup = loop.make_setup(settings, model, seed=0, extent=extent, num_views=len(views))
  return views, setup, loop.init_state(model, setup)


def scoring(devices, model, *, resolution, num_candidates, samples, rounds):
  """U of `num_candidates` cameras on a sphere around `model` (Eq. 10, M = `samples`),
  split over each device count."""
  import jax.numpy as jnp
  import numpy as np

  from mfsample import view_uncertainty as unc
  from mfsample.planning import poses
  from mfsample.renderer import RenderSettings
  from mfsample.samplers import sample_z

  sphere = poses.SphereSpec(radius=3.0, width=resolution, height=resolution)
  uv = poses.random_uv(np.random.default_rng(0), num_candidates, sphere).astype(np.float32)
  cams = poses.spherical_camera(jnp.asarray(uv), sphere)
  z = sample_z(model, samples, seed=6174)
  _, settings = unc.score_cameras(model, cams, z, settings=RenderSettings(
      max_intersections=512), num_devices=1)  # the budget that holds every candidate
  fns = {n: (lambda n=n: unc.score_cameras(model, cams, z, settings=settings,
                                           num_devices=n)[0].values) for n in devices}
  return summarize(alternate(fns, rounds), num_candidates), settings.max_intersections


def training(devices, views, setup, state, *, rounds):
  """The first training step (`setup`'s batch of `views`) split over each device count."""
  import dataclasses

  from mfsample import sharding
  from mfsample.data.datasets import to_device
  from mfsample.train import loop
  from mfsample.train.step import make_train_step

  data = to_device(views)
  data = (data.images, data.cameras)
  batch_size = setup.settings.batch_size
  index, rows = loop.step_targets(setup, 0, len(views))
  # One step on one device grows the budget until nothing overflows; every variant then
  # starts from that budget, so no timed step overflows.
  one = setup._replace(step_config=dataclasses.replace(setup.step_config, num_devices=1))
  for done in loop.run_steps(one, state, data, pick=lambda s: (index, rows), end=1):
    settings = done.setup.step_config.settings
  fns = {}
  for n in devices:
    cfg = dataclasses.replace(setup.step_config, settings=settings, num_devices=n)
    fn = make_train_step(cfg, setup.field)
    placed_data = sharding.replicated(data, n)
    placed = sharding.replicated(state, n)
    fns[n] = lambda fn=fn, d=placed_data, p=placed: fn(p, d, index, rows)[1].loss
  return summarize(alternate(fns, rounds), batch_size), settings.max_intersections


def main(argv):
  del argv
  # Before JAX starts: host devices for a CPU run (GPUs are unaffected).
  flag = f"--xla_force_host_platform_device_count={_HOST.value}"
  if "xla_force_host_platform_device_count" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + flag).strip()
  import jax

  from mfsample._bench import load_average, machine
  from mfsample._json import write_json

  devices = [int(n) for n in _DEVICES.value if int(n) <= jax.device_count()]
  skipped = [int(n) for n in _DEVICES.value if int(n) > jax.device_count()]
  if skipped:
    print(f"only {jax.device_count()} devices: skipping {skipped}")
  load_start = load_average()
  views, setup, state = setup_run(batch_size=_BATCH.value, resolution=_RES.value,
                                  points=_POINTS.value)
  score, score_budget = scoring(devices, state.model, resolution=_RES.value,
                                num_candidates=_CANDS.value, samples=_M.value,
                                rounds=_ROUNDS.value)
  train, train_budget = training(devices, views, setup, state, rounds=_ROUNDS.value)
  print(f"{'devices':>8} {'candidates/s':>13} {'speed-up':>9} {'CPU x':>6} "
        f"{'views/s':>9} {'speed-up':>9} {'CPU x':>6}")
  for n in devices:
    s, t = score[n], train[n]
    print(f"{n:>8} {s['per_second']:>13.1f} {s['speedup']:>9.2f} {s['cpu_ratio']:>6.2f} "
          f"{t['per_second']:>9.1f} {t['speedup']:>9.2f} {t['cpu_ratio']:>6.2f}")
  write_json(_OUT.value, {
      "machine": machine(), "load_average": {"start": load_start, "end": load_average()},
      "devices": devices, "rounds": _ROUNDS.value,
      "points": _POINTS.value,
      "scoring": {"resolution": _RES.value,
                  "num_candidates": _CANDS.value, "samples": _M.value, "budget": score_budget,
                  "by_devices": score},
      "training": {"batch_size": _BATCH.value, "resolution": _RES.value,
                   "budget": train_budget, "by_devices": train}})
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
  app.run(main)
