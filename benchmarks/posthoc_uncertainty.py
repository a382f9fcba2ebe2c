"""Post-hoc U of a pretrained model against the U of a jointly trained field.

A user's 3DGS model was trained without B_hat. `mfsample.train.fit_b_hat` fits B_hat
afterwards with the model frozen. Is that U as good a guide to the next view as the U of a
field trained jointly (the paper's)? Both are judged by the measure the project uses for
that question (`mfsample.planning.u_error`): Spearman's rho, over the unused candidate views,
between U of a candidate and the squared error of the model's own mean render there.

The comparison, defined once in `comparison_config()` (every field a flag, e.g.
`--comparison.seeds=0,1`), on the planning pool of a config (default: the main job's, the
built-in default scene at 64 x 64 with 100 candidates):

- view sets: the farthest-point trajectory of each seed, cut at a few view counts (as
  the candidates part of `experiments/uncertainty_quality.py`);
- joint: the protocol's round model of Ours (rank-2 low-rank field, `rounds.steps` steps,
  re-initialised, at the rounds' resolution);
- post-hoc: the protocol's deterministic round model on the same views with the same seed
  and steps (plain 3DGS, the "pretrained" model), written to a .ply, read back, and B_hat
  fitted to it with the round config's loss and learning rates for each of `posthoc_steps`
  steps (0: B_hat as initialised, nothing fitted);
- U with M = `samples` Sobol samples at the scoring size of the config; the error at full
  size; rho per case, then the mean over cases and each post-hoc row minus joint, paired by
  case (mean, standard error, cases above).

  python benchmarks/posthoc_uncertainty.py --out=workdirs/posthoc_uncertainty.json
"""

import itertools
import os
import tempfile
import time

import ml_collections
from absl import app, flags
from ml_collections import config_flags


def comparison_config():
  """The comparison (see the module docstring), a comment on every field."""
  c = ml_collections.ConfigDict()
  # Variant of configs/camera_planning.py whose pool and round models are compared ("": the
  # main job's: the built-in default scene, 400-step rounds at 32 x 32, lambda = 1e-4).
  c.planning_variant = ""
  c.seeds = (0, 1, 2, 3, 4, 5, 6, 7)  # Seeds: initial view, model initialisation, B_hat signs.
  c.views = (1, 3, 6, 9)  # Training-view counts at which each trajectory is cut.
  c.posthoc_steps = (0, 100, 400)  # Lengths of the B_hat fit (0: as initialised).
  c.samples = 8  # M of U (the planning config's select_samples).
  return c


_COMPARISON = config_flags.DEFINE_config_dict("comparison", comparison_config(),
                                              "The comparison (see comparison_config).")
_OUT = flags.DEFINE_string("out", "workdirs/posthoc_uncertainty.json", "JSON output.")


def _farthest_views(pool, config, seed, num_views):
  from mfsample.planning import runner, strategies

  config = config.copy_and_resolve_references()
  config.max_views = num_views
  selected, _ = runner.plan_views(strategies.make_strategy("farthest"), pool, config, seed,
                                  runner.Trainer(config, pool))
  return selected


def _posthoc_start(plan, ply_path, seed):
  """The stochastic field of `plan` (a `Recipe`) whose mean is the 3DGS model at `ply_path`
  (its SH degree the file's), B_hat fresh: the start of the post-hoc fit."""
  import numpy as np

  from mfsample.data.ply import load_ply, sh_degree_of

  init = plan.init.replace(init_from="ply", ply_path=ply_path,
                           sh_degree=sh_degree_of(load_ply(ply_path)))
  return plan._replace(init=init).initial_model(seed=seed, bounds=(np.zeros(3), np.ones(3)))


def run():
  import jax
  import numpy as np

  from mfsample.config_blocks import data_spec
  from mfsample.data.ply import export_ply
  from mfsample.jobs import Budgets
  from mfsample.planning import runner
  from mfsample.planning.config import get_config as planning_config
  from mfsample.planning.pool import make_pool
  from mfsample.planning.u_error import u_against_error
  from mfsample.samplers import sample_z
  from mfsample.train.posthoc import run_b_hat_fit

  comp = _COMPARISON.value
  config = planning_config(comp.planning_variant)
  config.data.progress = False
  pool = make_pool(data_spec(config.data))
  trainer = runner.Trainer(config, pool)
  # The round config's loss, learning rates and bounds, with the joint model's sampler.
  plan = runner.round_recipe(config, "lowrank")
  seeds, counts = [int(s) for s in comp.seeds], [int(v) for v in comp.views]
  trajectories = {seed: _farthest_views(pool, config, seed, max(counts)) for seed in seeds}
  down = int(config.rounds.downscale)
  pad_to = int(config.max_views)
  m = int(comp.samples)
  rows = {"joint": []} | {f"posthoc_{s}": [] for s in comp.posthoc_steps}
  seconds = {name: [] for name in rows}
  budgets = Budgets()
  tmp = tempfile.mkdtemp(prefix="posthoc_")
  for seed, n in itertools.product(seeds, counts):
    selected = trajectories[seed][:n]
    used = [view.index for view in selected]
    unused = np.setdiff1d(np.arange(len(pool.candidates)), used)
    t0 = time.perf_counter()
    joint, budgets = trainer.round_state("lowrank", selected, seed, budgets)
    seconds["joint"].append(time.perf_counter() - t0)
    plain, budgets = trainer.round_state("deterministic", selected, seed, budgets)
    ply = os.path.join(tmp, f"seed{seed}_views{n}.ply")
    export_ply(ply, plain.model)
    views = runner.as_views(selected, down)
    # Padded to the rounds' image slots (one compilation for every view count); the steps
    # draw among the n real views only.
    padded = views.subset(np.minimum(np.arange(pad_to), n - 1)).replace(names=())
    models = {"joint": joint.model}
    for steps in comp.posthoc_steps:
      t0 = time.perf_counter()
      model = _posthoc_start(plan, ply, seed)
      if int(steps) > 0:  # 0: B_hat as initialised, nothing fitted
        settings = plan.with_render(plain.settings).settings.replace(num_steps=int(steps))
        model = run_b_hat_fit(model, padded, settings, seed=seed, extent=plan.extent,
                              num_views=n).state.model
      jax.block_until_ready(model.params.b_hat)
      seconds[f"posthoc_{steps}"].append(time.perf_counter() - t0)
      models[f"posthoc_{steps}"] = model
    for name, model in models.items():
      z = sample_z(model, m, seed=int(config.strategy.ours.z_seed))
      res = u_against_error(model, pool.candidates.cameras[unused], z,
                            background=pool.background,
                            images=np.asarray(pool.candidates.images)[unused],
                            train_cameras=pool.candidates.cameras[np.asarray(used)],
                            center=pool.sphere.center,
                            score_downscale=int(config.strategy.ours.score_downscale),
                            score_settings=budgets.get("score"),
                            mean_settings=budgets.get("mean"))
      budgets = budgets.replace(score=res.score_settings, mean=res.mean_settings)
      rows[name].append({"seed": seed, "views": n, "rho_u_error": res.rho_u_error,
                         "rho_u_angle": res.rho_u_angle, "mean_error": float(res.error.mean())})
    print(f"seed {seed}, {n} views: " + ", ".join(
        f"{name} {rows[name][-1]['rho_u_error']:+.2f}" for name in rows), flush=True)

  summary = []
  base = np.asarray([r["rho_u_error"] for r in rows["joint"]])
  for name, cases in rows.items():
    rho = np.asarray([r["rho_u_error"] for r in cases])
    entry = {"model": name, "steps": (int(config.rounds.steps) if name == "joint"
                                      else int(name.split("_")[1])),
             "rho_u_error": float(rho.mean()),
             "rho_u_angle": float(np.mean([r["rho_u_angle"] for r in cases])),
             "mean_error": float(np.mean([r["mean_error"] for r in cases])),
             "seconds_median": float(np.median(seconds[name])),
             "cases": cases}
    if name != "joint":
      diff = rho - base
      entry["minus_joint"] = {"mean": float(diff.mean()),
                              "sem": float(diff.std(ddof=1) / np.sqrt(len(diff))),
                              "cases_above": int(np.sum(diff > 0)), "cases": len(diff)}
    summary.append(entry)
    extra = ""
    if "minus_joint" in entry:
      d = entry["minus_joint"]
      extra = (f"; minus joint {d['mean']:+.2f} +- {d['sem']:.2f} ({d['cases_above']}/"
               f"{d['cases']} cases above)")
    print(f"{name:>12}: {entry['steps']:4d} steps, {entry['seconds_median']:.1f} s (median), "
          f"rho(U, error) {entry['rho_u_error']:.2f}, rho(U, angle) "
          f"{entry['rho_u_angle']:.2f}{extra}", flush=True)
  return {"comparison": comp.to_dict(), "scene": pool.name,
          "resolution": [int(pool.candidates.images.shape[2]),
                         int(pool.candidates.images.shape[1])],
          "jax": jax.__version__, "devices": [str(d) for d in jax.devices()],
          "rows": summary}


def main(argv):
  del argv
  from mfsample._json import write_json
  write_json(_OUT.value, run())
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
