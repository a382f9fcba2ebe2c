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
checkpoint and records of a strategy's latest finished phase, `runs/<strategy>.json` a
finished strategy. A killed run restarts at the last finished phase. A workdir made with a
different config is refused, naming the fields (`check_resumable`), before anything is
written.
"""

import json
import os
import shutil
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import config_checks as cc
from mfsample import workdir as workdir_lib
from mfsample._json import write_json, write_text
from mfsample.lighting import captures as cap
from mfsample.lighting import evaluate as ev
from mfsample.lighting import field, strategies, tables, training
from mfsample.lighting import lights as lights_lib
from mfsample.lighting import optimize as opt_lib
from mfsample.lighting import uncertainty as lu
from mfsample.planning.poses import downscale_camera
from mfsample.renderer.settings import RenderSettings
from mfsample.uncertainty import uncertainty_z

# Fields that may change between calls on one workdir: which strategies to run, how the
# run is shown, and speed-only settings.
RESUME_FREE_FIELDS = ("strategies", "progress", "data.progress", "figures",
                      "render.chunks_per_step", "render.compositor")


# ------------------------------------------------------------------ config and workdir


def check_config(config):
  """Validates the fields the protocol reads (`mfsample.config_checks`): errors name them."""
  cc.check_int(config, "seed", minimum=0)
  cc.check_sequence(config, "strategies", item_choices=strategies.NAMES, distinct=True)
  n = cc.check_choice(config, "model.light_coeffs", field.COEFFICIENT_COUNTS[1:])
  cc.check_choice(config, "model.out_coeffs", field.COEFFICIENT_COUNTS)
  lights = cc.check_int(config, "num_lights", minimum=1)
  if "orthogonal" in config.strategies and lights > n:
    raise cc.ConfigError(f"config.num_lights = {lights}: the orthogonal strategy needs "
                         f"num_lights <= model.light_coeffs = {n} (a new direction per light)")
  cc.check_int(config, "steps_per_light", minimum=1)
  cc.check_choice(config, "data.kind", ("scene", "synthetic"))
  for f in ("data.width", "data.height"):
    cc.check_int(config, f, minimum=11)  # the SSIM window
  cc.check_int(config, "data.num_train", minimum=1)
  cc.check_int(config, "data.num_test", minimum=1)
  cc.check_int(config, "model.init_points", minimum=1)
  cc.check_float(config, "model.init_opacity", above=0.0, below=1.0)
  cc.check_choice(config, "sampler.kind", ("lowrank", "block", "diagonal", "deterministic"))
  cc.check_int(config, "sampler.rank", minimum=1)
  cc.check_sequence(config, "sampler.groups", min_length=0, distinct=True,
                    item_choices=tuple(field.group_shapes(16, 16)))
  cc.check_int(config, "sampler.num_samples", minimum=1)
  cc.check_float(config, "loss.volume_weight", minimum=0.0)
  cc.check_int(config, "loss.volume_every", minimum=1)
  cc.check_int(config, "planning.samples", minimum=2)
  cc.check_int(config, "planning.downscale", minimum=1)
  cc.check_int(config, "planning.ascent_steps", minimum=1)
  lr = cc.check_float(config, "planning.ascent_lr", above=0.0)
  cc.check_float(config, "planning.ascent_final_lr", above=0.0, maximum=lr)
  cc.check_int(config, "test_lights.num_environments", minimum=0)
  cc.check_int(config, "test_lights.num_random", minimum=0)
  if config.test_lights.num_environments + config.test_lights.num_random < 1:
    raise cc.ConfigError("config.test_lights: num_environments + num_random must be >= 1")
  cc.check_float(config, "test_lights.power", above=0.0)
  for f in ("render.max_intersections", "render.max_budget", "render.tile_size",
            "render.chunks_per_step"):
    cc.check_int(config, f, minimum=1)
  cc.check_float(config, "render.radius_sigma", above=0.0)
  cc.check_choice(config, "render.compositor", ("jnp", "pallas"))


def check_resumable(config, workdir):
  """Refuses to continue a workdir whose finished work used a different protocol.

  Raises:
    mfsample.workdir.WorkdirError: naming the differing fields.
  """
  workdir_lib.check_same_config(
      config, workdir, free_fields=RESUME_FREE_FIELDS,
      has_results=workdir_lib.holds_results(workdir, "shared", "runs"), results="work",
      remedy=f"use a new --workdir, or remove {workdir}/shared and {workdir}/runs to redo it")


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
  budgets: dict  # {purpose: RenderSettings}, updated in place


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
  return Context(config, data, test_lights, kinds, cap.capture_many(data.test_basis, test_lights),
                 cameras, downscale_camera(cameras, int(p.downscale)),
                 cap.to_device_cameras(data.test_cameras), lights_lib.UNIFORM_NORM,
                 opt_lib.AscentSettings(steps=int(p.ascent_steps), lr=float(p.ascent_lr),
                                        final_lr=float(p.ascent_final_lr)),
                 lpips_fn, {})


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


def _settings(config, budget):
  """The config's rasterisation rule and compositor with a starting `budget` (it grows)."""
  r = config.render
  return RenderSettings.holding(budget, tile_size=int(r.tile_size),
                                chunks_per_step=int(r.chunks_per_step),
                                radius_sigma=float(r.radius_sigma),
                                compositor=str(r.compositor))


def evaluate_phase(ctx: Context, model):
  """(test metrics, predictions [K, T, H, W, 3]) of `model` (updates the eval budget)."""
  settings = ctx.budgets.get("eval") or _settings(ctx.config, 1 << 14)
  metrics, pred, ctx.budgets["eval"] = ev.evaluate_relit(
      model, ctx.test_cameras, ctx.test_lights, ctx.test_truth, ctx.test_kinds,
      settings=settings, lpips_fn=ctx.lpips_fn)
  return metrics, pred


def gram_of(ctx: Context, model):
  """(Q, z) of U over the planning cameras for `model` (updates the "u" budget)."""
  p = ctx.config.planning
  z = uncertainty_z(model, int(p.samples), int(p.z_seed))
  settings = ctx.budgets.get("u") or _settings(ctx.config, 1 << 13)
  gram, ctx.budgets["u"] = lu.light_gram(model, ctx.plan_cameras, z, settings=settings)
  return np.asarray(gram.q, np.float64), z


def choose_light(ctx: Context, strategy, model, used, key):
  """One planning step: the strategy's next light given the model and the lights `used`.

  Returns:
    (light [n], record dict: the light, its U relative to the best on the sphere, the
    strategy's extras, the seconds it took, Q).
  """
  t0 = time.perf_counter()
  q, z = gram_of(ctx, model)
  inputs = strategies.LightInputs(
      model=model, cameras=ctx.plan_cameras, z=z, q=q, used=np.asarray(used), index=len(used),
      norm=ctx.norm, ascent=ctx.ascent, settings=dict(ctx.budgets),
      sobol_seed=int(ctx.config.planning.sobol_seed))
  choice = strategy.select(inputs, key)
  ctx.budgets.update(choice.info.pop("settings", {}))
  top, _ = lu.top_eigen(q)
  u = float(lu.quadratic_u(q, choice.light))
  u_max = ctx.norm ** 2 * top
  return choice.light, {"light": choice.light.tolist(), "u": u, "u_max": u_max,
                        "u_ratio": u / u_max if u_max > 0 else None, "info": choice.info,
                        "plan_seconds": time.perf_counter() - t0, "q": q.tolist()}


def strategy_key(config, name, index):
  """The PRNG key of strategy `name` choosing light `index`."""
  key = jax.random.PRNGKey(int(config.seed))
  return jax.random.fold_in(jax.random.fold_in(key, strategies.NAMES.index(name)), index)


# ------------------------------------------------------------------ the loop


def _shared_phase(ctx, setup, workdir, bar):
  """The first phase (uniform light), trained once or restored: (state, setup, record)."""
  config = ctx.config
  directory = os.path.join(workdir, "shared")
  record_path = os.path.join(directory, "record.json")
  if os.path.exists(record_path):
    state, setup, _ = training.restore_state(directory, config, setup, ctx.data.bounds)
    with open(record_path) as f:
      record = json.load(f)
    bar.update(int(config.steps_per_light))
    return state, setup, record
  used = lights_lib.uniform_light(ctx.data.light_coeffs)[None]
  images, lights = light_slots(ctx, used)
  state = training.init_state(config, setup, ctx.data.bounds)
  bar.set_postfix_str("uniform light")
  res = training.train_steps(config, setup, state, images, lights, ctx.cameras, num_lights=1,
                             phase_start=0, end=int(config.steps_per_light),
                             on_step=lambda _: bar.update(1))
  metrics, pred = evaluate_phase(ctx, res.state.model)
  q, _ = gram_of(ctx, res.state.model)
  record = {"lights": 1, "light": used[0].tolist(), "metrics": metrics,
            "train_seconds": res.seconds, "data_loss": res.data_loss, "q": q.tolist(),
            "live_gaussians": res.state.model.num_live}
  training.save_state(directory, res.state, res.setup, {"lights": 1})
  np.savez_compressed(os.path.join(directory, "relit.npz"), pred=pred.astype(np.float16))
  write_json(record_path, record, indent=1)
  return res.state, res.setup, record


def _run_strategy(ctx, name, shared, setup, workdir, bar):
  """All phases of one strategy after the shared one; resumes from its latest phase.

  Returns:
    (the strategy's record, the setup with the render budget that sufficed).
  """
  config = ctx.config
  total, steps = int(config.num_lights), int(config.steps_per_light)
  strategy = strategies.make_light_strategy(name)
  directory = os.path.join(workdir, "runs", name)
  restored = training.restore_state(directory, config, setup, ctx.data.bounds)
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
    light, record = choose_light(ctx, strategy, state.model, np.stack(used),
                                 strategy_key(config, name, len(used)))
    used.append(light)
    images, lights = light_slots(ctx, np.stack(used))
    start = (len(used) - 1) * steps
    res = training.train_steps(config, setup, state, images, lights, ctx.cameras,
                               num_lights=len(used), phase_start=start, end=start + steps,
                               on_step=lambda _: bar.update(1))
    state, setup = res.state, res.setup
    metrics, pred = evaluate_phase(ctx, state.model)
    record.update(lights=len(used), metrics=metrics, train_seconds=res.seconds,
                  data_loss=res.data_loss, live_gaussians=state.model.num_live)
    phases.append(record)
    training.save_state(directory, state, setup, {"phases": phases})
  if pred is None:  # every phase was restored (or L = 1): render the final model again
    _, pred = evaluate_phase(ctx, state.model)
  np.savez_compressed(os.path.join(workdir, "runs", f"{name}_relit.npz"),
                      pred=pred.astype(np.float16))
  return {"strategy": name, "label": strategy.label, "phases": phases[1:]}, setup


def _earlier_calls(workdir):
  """The `calls` of an earlier results.json in `workdir` (wall-clock and CPU time of every
  call that added to it), or []."""
  path = os.path.join(workdir, "results.json")
  if not os.path.exists(path):
    return []
  with open(path) as f:
    return list(json.load(f).get("calls", []))


def run_light_planning(config, workdir):
  """Runs the protocol for every strategy of `config`; writes and returns the results.

  Writes to `workdir`: `config.json`, `shared/` (the first phase), `runs/<strategy>.json`
  (each finished strategy; loaded, not recomputed, by a later call), `results.json` (with
  `calls`: the wall-clock and CPU time of every call on this workdir), `table.md`, and with
  `figures.enabled` `metrics.png`, `relit.png`, `u_sphere.png`.

  Returns:
    the results dict (as in `results.json`).
  """
  from tqdm.auto import tqdm

  t_start, cpu_start = time.perf_counter(), time.process_time()
  load_start = list(os.getloadavg())
  check_config(config)
  check_resumable(config, workdir)
  os.makedirs(os.path.join(workdir, "runs"), exist_ok=True)
  workdir_lib.write_config(config, workdir)
  t0, cpu0 = time.perf_counter(), time.process_time()
  data = cap.make_light_data(config.data, int(config.model.light_coeffs))
  capture_seconds, capture_cpu = time.perf_counter() - t0, time.process_time() - cpu0
  ctx = make_context(config, data)
  total, steps = int(config.num_lights), int(config.steps_per_light)
  setup = training.make_setup(config, data.train_cameras, total * steps)
  names = list(config.strategies)
  bar = tqdm(total=steps + len(names) * (total - 1) * steps, desc="light planning",
             unit="step", disable=not config.progress, dynamic_ncols=True)
  shared_state, setup, shared = _shared_phase(ctx, setup, workdir, bar)
  records, ran = [], []
  for name in names:
    path = os.path.join(workdir, "runs", f"{name}.json")
    if os.path.exists(path):
      with open(path) as f:
        records.append(json.load(f))
      bar.update((total - 1) * steps)
      continue
    t_run = time.perf_counter()
    # The budget that sufficed carries over (it changes no result, only compilations).
    record, grown = _run_strategy(ctx, name, shared_state, setup, workdir, bar)
    setup = setup._replace(step_config=grown.step_config)
    record["seconds"] = time.perf_counter() - t_run
    ran.append(name)
    write_json(path, record, indent=1)
    shutil.rmtree(os.path.join(workdir, "runs", name), ignore_errors=True)
    records.append(record)
  bar.close()

  summary = tables.summarise(shared, records)
  title = (f"Active illumination planning on `{data.name}`: relit test views "
           f"({len(data.test_cameras)} cameras x {len(ctx.test_lights)} held-out lights), "
           f"seed {config.seed}.")
  write_text(os.path.join(workdir, "table.md"), tables.report_markdown(summary, total, title))
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
  if config.figures.enabled:
    from mfsample.lighting import figures
    figures.write_figures(config, workdir, results, ctx)
  results["seconds_this_call"] = time.perf_counter() - t_start
  # CPU time of every thread of this process: on an otherwise idle machine the wall-clock
  # lies between this / (cores) and about this; under load, wall-clock alone misleads.
  results["cpu_seconds_this_call"] = time.process_time() - cpu_start
  results["calls"] = _earlier_calls(workdir) + [{
      "seconds": results["seconds_this_call"], "cpu_seconds": results["cpu_seconds_this_call"],
      "load_average": results["load_average"], "strategies_run": ran}]
  write_json(os.path.join(workdir, "results.json"), results, indent=1)
  return results
