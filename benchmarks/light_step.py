"""Cost of a relightable training step against a colour step, and of U(xi) and its gradient.

Both models start from the same random points in the same box, train on the same cameras and
image size, and run the jitted steps of their own trainers: the colour step of
`mfsample.train` (SH colour of degree `--sh_degree`, B_hat over every group, as the training
config) and the relightable step of `mfsample.lighting.training` (T of m x n x 3, B_hat over
T, as the light-planning config). Their data are the synthetic diffuse shell's captures
(`mfsample.data.datasets.load_light_data`): under the uniform light for the colour model,
under a few lights for the relightable one. The two steps run in turn, one of each at a
time, and the ratio of their median times is taken per round, so both see the same load.
Wall-clock and the process's CPU time are both recorded: on a machine shared with other
work the CPU time is the steadier of the two.

Then U(xi) (M = 2 samples, summed over the training cameras at 1 / `--u_downscale` of the
image size, as the protocol plans), its gradient w.r.t. xi, and the quadratic form Q are
timed (medians over `--repeats` calls, compilation excluded).

  python benchmarks/light_step.py --out=workdirs/light_step.json
"""

import json
import os
import platform
import statistics
import time

from absl import app, flags

_SIZE = flags.DEFINE_integer("size", 48, "Image side in pixels.")
_POINTS = flags.DEFINE_integer("points", 3000, "Gaussians of the initial cloud.")
_VIEWS = flags.DEFINE_integer("views", 12, "Training cameras.")
_OUT_COEFFS = flags.DEFINE_integer("out_coeffs", 4, "m of the relightable model.")
_LIGHT_COEFFS = flags.DEFINE_integer("light_coeffs", 16, "n of the relightable model.")
_SH_DEGREE = flags.DEFINE_integer("sh_degree", 1, "SH degree of the colour model.")
_ROUNDS = flags.DEFINE_integer("rounds", 3, "Interleaved rounds.")
_STEPS = flags.DEFINE_integer("steps", 30, "Timed steps per model and round.")
_REPEATS = flags.DEFINE_integer("repeats", 5, "Timed calls of U(xi), its gradient and Q.")
_U_DOWNSCALE = flags.DEFINE_integer("u_downscale", 2, "U is rendered at 1 / this of the size "
                                    "(the config's planning.downscale).")
_OUT = flags.DEFINE_string("out", "workdirs/light_step.json", "Output JSON.")


def _light_config():
  from mfsample.lighting.config import get_config

  config = get_config("tiny")
  config.data.width = config.data.height = _SIZE.value
  config.data.num_train = _VIEWS.value
  config.data.synthetic.num_gaussians = 400
  config.model.out_coeffs = _OUT_COEFFS.value
  config.model.light_coeffs = _LIGHT_COEFFS.value
  config.model.init_points = _POINTS.value
  config.render.max_intersections = 1 << 14
  return config


def _colour_recipe(light, extent):
  """The colour field's `Recipe`: the training job's rank-2 field of SH degree `--sh_degree`
  (B_hat over every group) from `--points` random points, every SH band from the first step,
  densification off, the relightable `light` recipe's render settings, on black."""
  from mfsample.groups import GROUPS
  from mfsample.samplers import SamplerSpec
  from mfsample.train import DensifySettings, InitSettings, TrainSettings
  from mfsample.train.initial import Recipe

  settings = TrainSettings(
      num_steps=100_000,  # only the Sobol rows and schedules follow it
      background=(0.0, 0.0, 0.0), sh_degree_every=1,  # the full SH degree from the first step
      densify=DensifySettings.off(), render=light.settings.render)
  init = InitSettings(sh_degree=_SH_DEGREE.value, init_points=_POINTS.value)
  return Recipe(settings, init, SamplerSpec.default(GROUPS, extent=extent), extent)


def _timed(fn, *args):
  """(wall seconds, CPU seconds of this process) of one call of fn(*args), and its output."""
  import jax

  t, c = time.perf_counter(), time.process_time()
  out = jax.block_until_ready(fn(*args))
  return time.perf_counter() - t, time.process_time() - c, out


def _grown(make_step, setup_settings, state, args):
  """Grows the budget until the first step does not overflow; returns the step function."""
  from mfsample.renderer.budget import fit_budget

  settings = setup_settings
  for _ in range(8):
    fn = make_step(settings)
    _, metrics = fn(state, *args(0))
    if not bool(metrics.overflow):
      return fn
    settings = fit_budget(settings, metrics)
  raise RuntimeError("the budget did not settle")


def run(rounds, steps, repeats):
  """The benchmark; returns its JSON dict (see the module docstring)."""
  import jax
  import jax.numpy as jnp
  import numpy as np

  from mfsample.config_blocks import data_spec
  from mfsample.data.datasets import load_light_data, scene_extent
  from mfsample.lighting import captures, lights, training
  from mfsample.lighting import uncertainty as lu
  from mfsample.lighting.config import light_recipe
  from mfsample.model import group_shapes
  from mfsample.samplers import sample_z
  from mfsample.train import loop
  from mfsample.train.step import make_train_step

  lc = _light_config()
  n = lc.model.light_coeffs
  data = load_light_data(data_spec(lc.data), n)
  cams = captures.to_device_cameras(data.train_cameras)
  num_views = len(data.train_cameras)
  num_lights = 4
  rng = np.random.default_rng(0)
  used = np.stack([lights.uniform_light(n)] + [lights.on_sphere(rng.normal(size=n))
                                               for _ in range(num_lights - 1)])
  images = jnp.asarray(np.stack([captures.capture(data.train_basis, x) for x in used]))
  light_array = jnp.asarray(used, jnp.float32)
  extent = lc.model.extent
  if extent is None:  # 3DGS's, from the training cameras (as the protocol)
    extent = scene_extent(data.train_cameras)
  lrecipe = light_recipe(lc, extent)
  # Only the Sobol rows and schedules follow the run's length: long enough for every round.
  lrecipe = lrecipe._replace(settings=lrecipe.settings.replace(num_steps=100_000))
  seed = int(lc.seed)
  lsetup, lstate = training.start(lrecipe, seed, data.bounds)

  # The same random points in the same box (the colour recipe's random start draws them as
  # the relightable one does).
  crecipe = _colour_recipe(lrecipe, extent)
  cmodel = crecipe.initial_model(seed=seed, bounds=data.bounds)
  csetup = loop.make_setup(crecipe.settings, cmodel, seed=seed, extent=extent,
                           num_views=num_views)
  cstate = loop.init_state(cmodel, csetup)
  colour_images = jnp.clip(images[0], 0.0, 1.0)

  def light_args(step):
    light, view = training.pair_for_step(seed, step, 0, num_views, num_lights)
    return ((images, light_array, cams),
            (jnp.asarray([light], jnp.int32), jnp.asarray([view], jnp.int32)),
            loop.step_rows(lsetup, step))

  def colour_args(step):
    return ((colour_images, cams), jnp.asarray([step % num_views], jnp.int32),
            loop.step_rows(csetup, step))

  light_fn = _grown(lambda s: make_train_step(lsetup.step_config.with_settings(s),
                                              lsetup.field),
                    lsetup.step_config.settings, lstate, light_args)
  colour_fn = _grown(lambda s: make_train_step(csetup.step_config.with_settings(s)),
                     csetup.step_config.settings, cstate, colour_args)

  def light_one(state):
    return light_fn(state, *light_args(int(state.step)))[0]

  def colour_one(state):
    return colour_fn(state, *colour_args(int(state.step)))[0]

  lstate = jax.block_until_ready(light_one(lstate))  # one untimed step each
  cstate = jax.block_until_ready(colour_one(cstate))
  table = []
  for r in range(rounds):
    # One step of each in turn: both see the same load, step by step.
    times = {"light": ([], []), "colour": ([], [])}
    for _ in range(steps):
      wall, cpu, lstate = _timed(light_one, lstate)
      times["light"][0].append(wall)
      times["light"][1].append(cpu)
      wall, cpu, cstate = _timed(colour_one, cstate)
      times["colour"][0].append(wall)
      times["colour"][1].append(cpu)
    med = {k: (statistics.median(w), statistics.median(c)) for k, (w, c) in times.items()}
    row = {"round": r, "light_ms": 1e3 * med["light"][0], "colour_ms": 1e3 * med["colour"][0],
           "ratio": med["light"][0] / med["colour"][0],
           "light_cpu_ms": 1e3 * med["light"][1], "colour_cpu_ms": 1e3 * med["colour"][1],
           "cpu_ratio": med["light"][1] / med["colour"][1], "load": os.getloadavg()[0]}
    table.append(row)
    print(f"round {r}: relightable {row['light_ms']:7.1f} ms/step ({row['light_cpu_ms']:.1f} "
          f"CPU ms), colour {row['colour_ms']:7.1f} ms/step ({row['colour_cpu_ms']:.1f} CPU "
          f"ms), ratio {row['ratio']:.2f} (CPU {row['cpu_ratio']:.2f}; load "
          f"{row['load']:.1f})", flush=True)

  from mfsample.planning.poses import downscale_camera

  model = lstate.model
  z = sample_z(model, 2, seed=6174)
  cams = downscale_camera(cams, _U_DOWNSCALE.value)
  xi = jnp.asarray(used[1], jnp.float32)
  _, settings = lu.light_uncertainty_fitted(model, cams, z, xi,
                                            settings=lsetup.step_config.settings)
  u_fn = jax.jit(lambda x: lu.light_uncertainty(model, cams, z, x, settings=settings).value)
  grad_fn = jax.jit(jax.grad(lambda x: lu.light_uncertainty(model, cams, z, x,
                                                            settings=settings).value))
  gram_fn = jax.jit(lambda: lu._light_gram(model, cams, z, settings=settings,
                                           num_devices=1).q)

  def timed(fn, *args):
    jax.block_until_ready(fn(*args))  # compiled
    walls, cpus = [], []
    for _ in range(repeats):
      wall, cpu, _ = _timed(fn, *args)
      walls.append(wall)
      cpus.append(cpu)
    return 1e3 * statistics.median(walls), 1e3 * statistics.median(cpus)

  (u_ms, u_cpu), (grad_ms, grad_cpu) = timed(u_fn, xi), timed(grad_fn, xi)
  gram_ms, gram_cpu = timed(gram_fn)
  print(f"U(xi) over {len(data.train_cameras)} cameras at {cams.width} x {cams.height}, "
        f"M = 2: {u_ms:.1f} ms ({u_cpu:.1f} CPU ms); dU/dxi: {grad_ms:.1f} ms ({grad_cpu:.1f} "
        f"CPU ms); Q ({n} x {n}): {gram_ms:.1f} ms ({gram_cpu:.1f} CPU ms)", flush=True)
  ratios = [row["ratio"] for row in table]
  return {
      "machine": {"platform": platform.platform(), "cpu_count": os.cpu_count(),
                  "jax": jax.__version__, "device": str(jax.devices()[0])},
      "size": _SIZE.value, "points": _POINTS.value, "views": len(data.train_cameras),
      "out_coeffs": int(lc.model.out_coeffs), "light_coeffs": n,
      "colour_sh_degree": _SH_DEGREE.value, "u_size": [cams.width, cams.height],
      "params_per_gaussian": {
          "relightable": int(sum(np.prod(x.shape[1:])
                                 for x in jax.tree.leaves(lstate.model.params))),
          "colour": int(sum(np.prod(x.shape[1:]) for x in jax.tree.leaves(cstate.model.params)))},
      "colour_groups": list(group_shapes(_SH_DEGREE.value)),
      "rounds": table, "ratio_median": statistics.median(ratios),
      "cpu_ratio_median": statistics.median(r["cpu_ratio"] for r in table),
      "light_ms_median": statistics.median(r["light_ms"] for r in table),
      "colour_ms_median": statistics.median(r["colour_ms"] for r in table),
      "u_ms": u_ms, "grad_ms": grad_ms, "gram_ms": gram_ms,
      "u_cpu_ms": u_cpu, "grad_cpu_ms": grad_cpu, "gram_cpu_ms": gram_cpu,
  }


def main(argv):
  del argv
  from mfsample._json import write_json

  out = run(_ROUNDS.value, _STEPS.value, _REPEATS.value)
  print(json.dumps({k: out[k] for k in ("ratio_median", "cpu_ratio_median", "light_ms_median",
                                        "colour_ms_median", "u_ms", "grad_ms", "gram_ms")},
                   indent=1))
  write_json(_OUT.value, out)
  print(f"saved {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
