"""The active illumination planning protocol (paper Sec. 5.2): pure steps, a thin resumable loop.

1. Captures: the basis images of the fixed training and test cameras (`captures`); the
   held-out test lights and their ground truth (`lights.held_out_lights`).
2. The first phase, shared by every strategy: a relightable field trained `steps_per_light`
   steps under the uniform light (the paper starts from it).
3. For every strategy, for l = 2..L: the strategy chooses light l from the model of the
   previous phase (`strategies`; U over the training cameras), its captures at the training
   cameras are taken (the oracle's basis images relit: no rendering), and the same training
   run continues `steps_per_light` steps on the l lights (the paper's text: one run, a light
   added every so many steps).
4. After every phase the mean model is evaluated on the test cameras under the test lights
   (`evaluate`): PSNR / SSIM / LPIPS against the number of lights.

For every chosen light the record also keeps U of that light relative to the largest U on
the sphere (xi^T Q xi / (norm^2 lambda_max) under that phase's Q), so each strategy's lights
can be compared by the quantity Ours maximises.

Resume: `shared/` holds the first phase (checkpoint and record), `runs/<strategy>/` the
checkpoint and records of a strategy's latest finished phase, `runs/<strategy>.json` and
`runs/<strategy>_relit.npz` a finished strategy. A killed run restarts at the last finished
phase; a damaged record, array or checkpoint is reported and that part computed again. A
workdir made with a different config is refused, naming the fields (`JOB`), before anything
is written.
"""

import os
import shutil
import time
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import jobs
from mfsample.config_blocks import data_spec, speed_only_fields
from mfsample.data.datasets import load_light_data, scene_extent
from mfsample.jobs import Budgets
from mfsample.lighting import captures as cap
from mfsample.lighting import evaluate as ev
from mfsample.lighting import lights as lights_lib
from mfsample.lighting import optimize as opt_lib
from mfsample.lighting import strategies, tables, training
from mfsample.lighting import uncertainty as lu
from mfsample.lighting.config import ascent_settings, light_recipe, validate
from mfsample.planning.poses import downscale_camera
from mfsample.samplers import sample_z
from mfsample.train.checkpoint import CorruptCheckpointError

# ------------------------------------------------------------------ pure pieces


class Context(NamedTuple):
  """Everything a phase needs that does not change during a run."""

  config: object
  data: cap.LightData
  test_lights: np.ndarray  # [K, n]
  test_kinds: tuple  # K strings
  test_truth: np.ndarray  # [K, T, H, W, 3]
  cameras: object  # training `Camera` [V], jnp leaves
  plan_cameras: object  # the same at 1 / planning.downscale
  test_cameras: object
  norm: float
  ascent: opt_lib.AscentSettings
  lpips_fn: object
  recipe: training.LightRecipe  # the field's training, start and sampler


def make_context(config, data):
  """The `Context` of a run on `data`."""
  n = int(config.model.light_coeffs)
  tl = config.test_lights
  test_lights, kinds = lights_lib.held_out_lights(
      n, num_environments=int(tl.num_environments), num_random=int(tl.num_random),
      seed=int(tl.seed), power=float(tl.power), sharpness=tuple(tl.sharpness))
  cameras = cap.to_device_cameras(data.train_cameras)
  p = config.planning
  lpips_fn = None
  if config.eval.lpips_net:
    from mfsample.metrics import make_lpips
    lpips_fn = make_lpips(config.eval.lpips_net)
  extent = config.model.extent
  if extent is None:  # 3DGS's, from the training cameras
    extent = scene_extent(data.train_cameras)
  return Context(config, data, test_lights, kinds, cap.capture_many(data.test_basis, test_lights),
                 cameras, downscale_camera(cameras, int(p.downscale)),
                 cap.to_device_cameras(data.test_cameras), lights_lib.UNIFORM_NORM,
                 ascent_settings(config), lpips_fn, light_recipe(config, extent))


def light_slots(ctx: Context, used):
  """Device arrays (images [L, V, H, W, 3], lights [L, n]) of the lights `used` [l, n], padded
  to L = config.num_lights slots with zeros (never drawn)."""
  total = int(ctx.config.num_lights)
  n = ctx.data.light_coeffs
  lights = np.zeros((total, n))
  lights[:len(used)] = used
  images = np.zeros((total,) + ctx.data.train_basis.shape[:1] + ctx.data.train_basis.shape[2:],
                    np.float32)
  for i, xi in enumerate(used):
    images[i] = cap.capture(ctx.data.train_basis, xi)
  return jnp.asarray(images), jnp.asarray(lights, jnp.float32)


def _settings(ctx: Context, budget):
  """The run's rasterisation rule and compositor with a starting `budget` (it grows)."""
  return ctx.recipe.settings.render.holding_budget(budget)


def evaluate_phase(ctx: Context, model, budgets: Budgets):
  """(test metrics, predictions [K, T, H, W, 3], budgets) of `model`."""
  metrics, pred, settings = ev.evaluate_relit(
      model, ctx.test_cameras, ctx.test_lights, ctx.test_truth, ctx.test_kinds,
      settings=budgets.get("eval") or _settings(ctx, 1 << 14), lpips_fn=ctx.lpips_fn)
  return metrics, pred, budgets.replace(eval=settings)


def gram_of(ctx: Context, model, budgets: Budgets):
  """(Q, z, budgets) of U over the planning cameras for `model`."""
  p = ctx.config.planning
  z = sample_z(model, int(p.samples), seed=int(p.z_seed))
  gram, settings = lu.light_gram(model, ctx.plan_cameras, z,
                                 settings=budgets.get("u") or _settings(ctx, 1 << 13))
  return np.asarray(gram.q, np.float64), z, budgets.replace(u=settings)


def choose_light(ctx: Context, strategy, model, used, key, budgets: Budgets):
  """One planning step: the strategy's next light given the model and the lights `used`.

  Returns:
    (light [n], record dict: the light, its U relative to the best on the sphere, the
    strategy's extras, the seconds it took, Q; the budgets that sufficed).
  """
  t0 = time.perf_counter()
  q, z, budgets = gram_of(ctx, model, budgets)
  inputs = strategies.LightInputs(
      model=model, cameras=ctx.plan_cameras, z=z, q=q, used=np.asarray(used), index=len(used),
      norm=ctx.norm, ascent=ctx.ascent,
      renders=strategies.LightRenders(budgets.get("u"), budgets.get("ascent")),
      sobol_seed=int(ctx.config.planning.sobol_seed))
  choice = strategy.select(inputs, key)
  top, _ = lu.top_eigen(q)
  u = float(lu.quadratic_u(q, choice.light))
  u_max = ctx.norm ** 2 * top
  return choice.light, {"light": choice.light.tolist(), "u": u, "u_max": u_max,
                        "u_ratio": u / u_max if u_max > 0 else None, "info": choice.info,
                        "plan_seconds": time.perf_counter() - t0, "q": q.tolist()}, \
      budgets.replace(ascent=choice.renders.ascent)


# ------------------------------------------------------------------ the loop


def _restored(directory, ctx, setup):
  """`training.restore_state`, or None (with a warning) when no checkpoint there is intact:
  the phase is then trained again."""
  try:
    return training.restore_state(directory, ctx.recipe, setup, ctx.data.bounds)
  except CorruptCheckpointError as e:
    warnings.warn(f"{e}; the phase is trained again", stacklevel=2)
    return None


def _shared_phase(ctx, setup, wd, bar, budgets):
  """The first phase (uniform light), trained once or restored: (state, setup, record,
  budgets)."""
  config = ctx.config
  directory = wd.file("shared")
  record = wd.read_json("shared/record.json")
  restored = None
  if record is not None:
    restored = _restored(directory, ctx, setup)
  if restored is not None:
    state, setup, _ = restored
    bar.update(int(config.steps_per_light))
    return state, setup, record, budgets
  used = lights_lib.uniform_light(ctx.data.light_coeffs)[None]
  images, lights = light_slots(ctx, used)
  state = training.initial_state(ctx.recipe, setup, ctx.data.bounds)
  bar.set_postfix_str("uniform light")
  res = training.train_steps(setup, state, images, lights, ctx.cameras, num_lights=1,
                             phase_start=0, end=int(config.steps_per_light),
                             on_step=lambda _: bar.update(1))
  metrics, pred, budgets = evaluate_phase(ctx, res.state.model, budgets)
  q, _, budgets = gram_of(ctx, res.state.model, budgets)
  record = {"lights": 1, "light": used[0].tolist(), "metrics": metrics,
            "train_seconds": res.seconds, "data_loss": res.data_loss, "q": q.tolist(),
            "live_gaussians": res.state.model.num_live}
  training.save_state(directory, res.state, res.setup, {"lights": 1})
  wd.save_arrays("shared/relit.npz", pred=pred.astype(np.float16))
  wd.write_json("shared/record.json", record,  # last: marks the phase done
                files=("shared/relit.npz",))
  return res.state, res.setup, record, budgets


def _run_strategy(ctx, name, shared, setup, wd, bar, budgets):
  """All phases of one strategy after the shared one; resumes from its latest phase.

  Returns:
    (the strategy's record, its final test predictions [K, T, H, W, 3], the setup with the
    render budget that sufficed, the budgets).
  """
  config = ctx.config
  total, steps = int(config.num_lights), int(config.steps_per_light)
  strategy = strategies.make_light_strategy(name)
  restored = _restored(wd.file("runs", name), ctx, setup)
  if restored is not None:
    state, setup, meta = restored
    phases = meta["phases"]
    bar.update((len(phases) - 1) * steps)
  else:
    state, phases = shared, [None]  # phases[0]: the shared phase (filled in by the caller)
  used = [np.asarray(lights_lib.uniform_light(ctx.data.light_coeffs))]
  used += [np.asarray(p["light"]) for p in phases[1:]]
  pred = None
  while len(used) < total:
    bar.set_postfix_str(f"{strategy.label}, light {len(used) + 1}")
    light, record, budgets = choose_light(
        ctx, strategy, state.model, np.stack(used),
        strategies.strategy_key(config.seed, name, len(used)), budgets)
    used.append(light)
    images, lights = light_slots(ctx, np.stack(used))
    start = (len(used) - 1) * steps
    res = training.train_steps(setup, state, images, lights, ctx.cameras,
                               num_lights=len(used), phase_start=start, end=start + steps,
                               on_step=lambda _: bar.update(1))
    state, setup = res.state, res.setup
    metrics, pred, budgets = evaluate_phase(ctx, state.model, budgets)
    record.update(lights=len(used), metrics=metrics, train_seconds=res.seconds,
                  data_loss=res.data_loss, live_gaussians=state.model.num_live)
    phases.append(record)
    training.save_state(wd.file("runs", name), state, setup, {"phases": phases})
  if pred is None:  # every phase was restored (or L = 1): render the final model again
    _, pred, budgets = evaluate_phase(ctx, state.model, budgets)
  return ({"strategy": name, "label": strategy.label, "phases": phases[1:]}, pred, setup,
          budgets)


def run_light_planning(config, workdir):
  """Runs the protocol for every strategy of `config`; writes and returns the results.

  Writes to `workdir`: `config.json`, `shared/` (the first phase), `runs/<strategy>.json`
  and `runs/<strategy>_relit.npz` (each finished strategy; loaded, not recomputed, by a
  later call), `results.json` (with `calls`: the wall-clock and CPU time of every call on
  this workdir), `table.md`, and with `figures.enabled` `metrics.png`, `relit.png`,
  `u_sphere.png`.

  Returns:
    the results dict (as in `results.json`).
  """
  t_start, cpu_start = time.perf_counter(), time.process_time()
  load_start = list(os.getloadavg())
  with jobs.open_workdir(JOB, config, workdir) as wd:
    t0, cpu0 = time.perf_counter(), time.process_time()
    wd.stage(f"capturing the views under the basis lights ({config.data.kind} data)")
    data = load_light_data(data_spec(config.data), int(config.model.light_coeffs))
    capture_seconds, capture_cpu = time.perf_counter() - t0, time.process_time() - cpu0
    wd.write_config()
    ctx = make_context(config, data)
    total, steps = int(config.num_lights), int(config.steps_per_light)
    setup, _ = training.start(ctx.recipe, int(config.seed), data.bounds)
    names = list(config.strategies)
    bar = wd.progress(steps + len(names) * (total - 1) * steps, unit="step")
    budgets = Budgets()
    shared_state, setup, shared, budgets = _shared_phase(ctx, setup, wd, bar, budgets)
    records, predictions, ran = [], {}, []
    for name in names:
      record = wd.read_json(f"runs/{name}.json")
      relit = wd.load_arrays(f"runs/{name}_relit.npz", keys=("pred",))
      if record is not None and relit is not None:
        records.append(record)
        predictions[name] = relit["pred"]
        bar.update((total - 1) * steps)
        continue
      t_run = time.perf_counter()
      # The budget that sufficed carries over (it changes no result, only compilations).
      record, pred, grown, budgets = _run_strategy(ctx, name, shared_state, setup, wd, bar,
                                                   budgets)
      setup = setup._replace(step_config=grown.step_config)
      record["seconds"] = time.perf_counter() - t_run
      ran.append(name)
      predictions[name] = pred.astype(np.float16)
      wd.save_arrays(f"runs/{name}_relit.npz", pred=predictions[name])
      wd.write_json(f"runs/{name}.json", record,  # after its arrays: marks the strategy done
                    files=(f"runs/{name}_relit.npz",))
      shutil.rmtree(wd.file("runs", name), ignore_errors=True)
      records.append(record)
    bar.close()

    summary = tables.summarise(shared, records)
    title = (f"Active illumination planning on `{data.name}`: relit test views "
             f"({len(data.test_cameras)} cameras x {len(ctx.test_lights)} held-out lights), "
             f"seed {config.seed}.")
    wd.write_text("table.md", tables.report_markdown(summary, total, title))
    earlier = wd.read_json("results.json") or {}
    results = {
        "scene": data.name,
        "resolution": [int(data.train_basis.shape[3]), int(data.train_basis.shape[2])],
        "num_train": len(data.train_cameras), "num_test": len(data.test_cameras),
        "out_coeffs": int(config.model.out_coeffs), "light_coeffs": data.light_coeffs,
        "num_lights": total, "steps_per_light": steps, "norm": ctx.norm,
        "test_lights": ctx.test_lights.tolist(), "test_kinds": list(ctx.test_kinds),
        "strategies": names, "summary": summary, "shared": shared, "runs": records,
        "capture_seconds": capture_seconds, "capture_cpu_seconds": capture_cpu,
        "seconds_this_call": time.perf_counter() - t_start,
        "load_average": {"start": load_start, "end": list(os.getloadavg())},
        "jax_version": jax.__version__,
    }
    if config.figures.enabled and wd.writes:
      from mfsample.lighting import figures
      wd.stage("figures")
      figures.write_figures(config, wd.path, results, ctx, predictions)
    results["seconds_this_call"] = time.perf_counter() - t_start
    # CPU time of every thread of this process: on an otherwise idle machine the wall-clock
    # lies between this / (cores) and about this; under load, wall-clock alone misleads.
    results["cpu_seconds_this_call"] = time.process_time() - cpu_start
    results["calls"] = list(earlier.get("calls", [])) + [{
        "seconds": results["seconds_this_call"],
        "cpu_seconds": results["cpu_seconds_this_call"],
        "load_average": results["load_average"], "strategies_run": ran}]
    wd.write_json("results.json", results)
    return results


# Fields a later call on the same workdir may change: which strategies to run, how the run
# is shown, and speed-only settings.
FREE_FIELDS = ("strategies", "progress", "data.progress", "figures") + speed_only_fields()
JOB = jobs.Job("light planning", "light_planning", run_light_planning, validate, FREE_FIELDS,
               ("shared", "runs"), report=jobs.table_report)
