"""Does gradient ascent on the camera raise U? Ours (Opt. Sel.) replayed round by round.

Ours (Opt. Sel.) starts at the candidate with the highest U and runs Adam on -U over the
camera sphere (paper Sec. 4.4). This script replays the Ours (Opt. Sel.) runs of a finished
planning run (its `results.json`): for every seed and round, the round model on the run's
first k views (the protocol's `Trainer`: deterministic, the run's own model, or with
`--config.strategy.optimize.sampler` another sampler's), the candidate the optimisation
started from, and the pose that each optimisation setting in `--settings` (below) reaches
from there. It measures:

- U with the selection's M and unscaled z (the number that chose the start) at the start
  and at the end: their ratio, and the end pose's rank among all candidates;
- how smooth U is where the optimisation starts: along the gradient direction, the
  autodiff directional derivative against central finite differences with steps of
  1e-4 and 1e-3 in (u, v) (1e-3 in u is 0.36 degrees of azimuth), with the renderer as
  configured and with its alpha, radius and transmittance cut-offs switched off (if the
  jumps stay, they come from elsewhere: the depth order of the splats).

  PYTHONPATH=. python benchmarks/view_optimisation.py
  PYTHONPATH=. python benchmarks/view_optimisation.py --seeds=0 --settings=2:3.3e-3,8:5e-4
  PYTHONPATH=. python benchmarks/view_optimisation.py --seeds=0 \
      --config.strategy.optimize.sampler=diagonal --settings=2:3.3e-3:resample:nodrop

Settings: M:lr, then optional flags: nocut (the renderer's cut-offs off), resample (fresh z
every step), nodrop (no z drop), sN (N steps, the z drop at N / 2).
"""

import functools
import json

from absl import app, flags
from ml_collections import config_flags

_CONFIG = config_flags.DEFINE_config_file(
    "config", "configs/camera_planning.py", "The planning config of the run.",
    lock_config=False)
_RESULTS = flags.DEFINE_string(
    "results", "results/camera_planning_default/results.json", "results.json of the run.")
_SEEDS = flags.DEFINE_list("seeds", [], "Seeds (default: all of the run's).")
_SETTINGS = flags.DEFINE_list(
    "settings", ["2:3.3e-3", "8:3.3e-3", "2:5e-4", "8:5e-4"],
    "Optimisation settings as M:lr with optional flags :nocut (optimise with the renderer's "
    "cut-offs off), :resample (fresh z every step), :nodrop (no z drop) and :sN (N steps, "
    "the z drop at N / 2; default: the config's steps and drop); the config's: 2:3.3e-3.")
_OUT = flags.DEFINE_string("out", "results/view_optimisation.json", "JSON output.")


def _smoothness(u_of, uv0):
  """Autodiff vs central finite differences of U along its gradient direction at uv0.

  `u_of(uv)` returns (U, its render's overflow flags); returns (the comparison, whether the
  render at uv0 overflowed its budget).
  """
  import jax
  import jax.numpy as jnp

  (value, overflow), grad = jax.value_and_grad(u_of, has_aux=True)(uv0)
  norm = float(jnp.linalg.norm(grad))
  direction = grad / jnp.maximum(norm, 1e-30)
  out = {"u": float(value), "autodiff": norm}
  for h in (1e-4, 1e-3):
    ahead, behind = u_of(uv0 + h * direction)[0], u_of(uv0 - h * direction)[0]
    out[f"fd_{h:g}"] = float((ahead - behind) / (2 * h))
  return out, bool(jnp.any(overflow))


def _no_cutoffs(settings):
  """The renderer without its alpha, radius and transmittance cut-offs (more budget)."""
  return settings.replace(alpha_min=0.0, radius_sigma=6.0, transmittance_min=1e-9,
                          max_intersections=8 * settings.max_intersections)


def main(argv):
  del argv
  import jax
  import jax.numpy as jnp
  import numpy as np
  from tqdm.auto import tqdm

  from mfsample import uncertainty as unc
  from mfsample.planning import optimize, poses, strategies
  from mfsample.planning.pool import make_pool
  from mfsample.planning.runner import Trainer, selected_from_record
  from mfsample.planning.workdirs import check_run_matches
  from mfsample.render.settings import RenderSettings

  config = _CONFIG.value
  with open(_RESULTS.value) as f:
    results = json.load(f)
  seeds = [int(s) for s in _SEEDS.value] or [int(s) for s in results["seeds"]]
  runs = [r for r in results["runs"] if r["strategy"] == "ours_opt_sel" and r["seed"] in seeds]
  if not runs:
    raise ValueError(f"{_RESULTS.value} has no ours_opt_sel run for seeds {seeds}")
  variants = []
  for spec in _SETTINGS.value:
    m, lr, *flags_ = spec.split(":")
    steps = [int(f[1:]) for f in flags_ if f[:1] == "s" and f[1:].isdigit()]
    if not set(flags_) <= {"nocut", "resample", "nodrop", *(f"s{n}" for n in steps)}:
      raise ValueError(f"--settings entries are M:lr[:nocut][:resample][:nodrop][:sN], "
                       f"got {spec!r}")
    variants.append((int(m), float(lr), "nocut" in flags_, "resample" in flags_,
                     "nodrop" in flags_, steps[0] if steps else None))

  pool = make_pool(config.data)
  check_run_matches(pool, results)
  trainer = Trainer(config, pool)
  model_kind = strategies.make_strategy("ours_opt_sel", config).model_kind
  s = config.strategy
  down = int(s.optimize.downscale)
  sphere = pool.sphere.replace(width=max(pool.sphere.width // down, 1),
                               height=max(pool.sphere.height // down, 1))
  candidates = poses.downscale_camera(pool.candidates.cameras, int(s.ours.score_downscale))
  if (candidates.width, candidates.height) != (sphere.width, sphere.height):
    raise ValueError("the config scores and optimises at different sizes; ranks would mix them")
  bg = jnp.asarray(pool.background, jnp.float32)
  m_select = int(s.ours.select_samples)
  budget = {"score": RenderSettings(max_intersections=1 << 12),
            "opt": RenderSettings(max_intersections=1 << 12)}

  # Compiled once for the whole replay (per budget): a closure jitted afresh in every round
  # would be traced and compiled again each time, the probe's value and its gradient alike.
  @functools.partial(jax.jit, static_argnames=("settings",))
  def uncertainty_at(uv, model, z, settings):
    return unc.uncertainty(model, poses.spherical_camera(uv, sphere), z, settings=settings,
                           background=bg)

  rows = []
  bar = tqdm(total=sum(len(r["indices"]) - 1 for r in runs), desc="rounds")
  for run in runs:
    seed = int(run["seed"])
    selected = selected_from_record(run, pool)
    for k in range(1, len(selected)):
      model = trainer.round_model(model_kind, selected[:k], seed)
      uv0 = poses.project_uv(jnp.asarray(run["optimisation"][k]["uv0"], jnp.float32), sphere)
      z_select = unc.uncertainty_z(model, m_select, int(s.ours.z_seed))
      ends = {}
      for m, lr, nocut, resample, nodrop, steps in variants:
        opt = optimize.OptimizeSettings(
            steps=steps or int(s.optimize.steps), lr=lr,
            z_drop_step=steps // 2 if steps else int(s.optimize.z_drop_step),
            z_drop_scale=1.0 if nodrop else float(s.optimize.z_drop_scale), resample_z=resample)
        result = optimize.optimize_spherical(
            model, uv0, unc.uncertainty_z(model, m, int(s.ours.z_seed)), sphere=sphere,
            opt=opt, settings=_no_cutoffs(budget["opt"]) if nocut else budget["opt"],
            background=bg, key=jax.random.fold_in(jax.random.key(seed), k))
        if not nocut:
          budget["opt"] = result.settings
        name = (f"M={m}, lr={lr:g}" + (f", {steps} steps" if steps else "")
                + (", no cut-offs" if nocut else "")
                + (", fresh z every step" if resample else "") + (", no z drop" if nodrop else ""))
        ends[name] = result.params
      cams = poses.spherical_camera(jnp.stack([uv0, *ends.values()]), sphere)
      scored, budget["score"] = unc.score_cameras(
          model, cams, z_select, settings=budget["score"], background=bg, num_devices=1)
      all_u, budget["score"] = unc.score_cameras(
          model, candidates, z_select, settings=budget["score"], background=bg, num_devices=1)
      u = np.asarray(scored.values, np.float64)
      all_u = np.asarray(all_u.values, np.float64)
      smooth = {}
      for name, settings in (("renderer", budget["score"]), ("no_cutoffs", _no_cutoffs(
          budget["score"]))):

        def u_of(uv, model=model, z=z_select, settings=settings):
          out = uncertainty_at(uv, model, z, settings)
          return out.value, out.stats.overflow

        smooth[name], overflowed = _smoothness(u_of, uv0)
        if overflowed:
          raise RuntimeError(f"the {name} probe overflowed its budget at the start")
      rows.append({
          "seed": seed, "views": k, "u_start": u[0], "smoothness": smooth,
          "variants": {name: {"u_end": float(u[i + 1]), "ratio": float(u[i + 1] / u[0]),
                              "rank_among_candidates": int(np.sum(all_u > u[i + 1])) + 1,
                              "uv_travel": float(np.linalg.norm(np.asarray(p) - np.asarray(uv0)))}
                       for i, (name, p) in enumerate(ends.items())}})
      bar.update(1)
  bar.close()

  print(f"\nU (M = {m_select}, unscaled z) at the end of the optimisation / at its start, "
        f"{len(rows)} rounds (seeds {seeds}):")
  print("| optimisation | mean ratio | rounds where U rose | median rank of the end pose |")
  print("|---|---:|---:|---:|")
  summary = {}
  for name in rows[0]["variants"]:
    ratio = np.asarray([r["variants"][name]["ratio"] for r in rows])
    rank = np.asarray([r["variants"][name]["rank_among_candidates"] for r in rows])
    summary[name] = {"mean_ratio": float(ratio.mean()), "rose": int(np.sum(ratio > 1.0)),
                     "rounds": len(rows), "median_rank": float(np.median(rank))}
    print(f"| {name} | {ratio.mean():.2f} | {int(np.sum(ratio > 1))} / {len(rows)} | "
          f"{np.median(rank):g} / {len(pool.candidates)} |")
  print("\nalong the gradient at the start: finite difference / autodiff derivative")
  for probe in ("renderer", "no_cutoffs"):
    ad = np.asarray([r["smoothness"][probe]["autodiff"] for r in rows])
    fd4 = np.asarray([r["smoothness"][probe]["fd_0.0001"] for r in rows])
    fd3 = np.asarray([r["smoothness"][probe]["fd_0.001"] for r in rows])
    summary[f"smoothness_{probe}"] = {
        "median_fd1e-4_over_autodiff": float(np.median(fd4 / ad)),
        "median_fd1e-3_over_autodiff": float(np.median(fd3 / ad)),
        "fd1e-3_points_downhill": int(np.sum(fd3 < 0)), "rounds": len(rows)}
    print(f"  {probe}: median {np.median(fd4 / ad):.2f} (h = 1e-4), "
          f"{np.median(fd3 / ad):.2f} (h = 1e-3); the h = 1e-3 difference points downhill "
          f"in {int(np.sum(fd3 < 0))} / {len(rows)}")
  from mfsample._json import write_json
  write_json(_OUT.value, {"results": _RESULTS.value, "seeds": seeds,
                          "select_samples": m_select, "round_model": model_kind,
                          "summary": summary, "rows": rows}, indent=1)
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
