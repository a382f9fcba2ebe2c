"""Does U follow the round model's error at the candidates? Round length, M and sampler.

Ours (Sel.) picks the candidate with the highest U (Eq. 10): that helps only if U ranks the
candidates as the current model's error there does, the paper's premise. On the planning
pool of `candidates.planning` (default: the main job's, the built-in default scene):

- view sets: the farthest-point trajectory of each seed (model-free, the same for every
  setting), cut at `candidates.views` view counts;
- for every (round steps, sampler, M): the protocol's round model (`rounds.steps` steps,
  re-initialised; the sampler "kind" or "kind:k"), U of every unused candidate at the
  scoring resolution and the mean squared error of the mean render at full resolution
  (`mfsample.planning.u_error.u_against_error`);
- Spearman's rho of U against that error, and of both against the angle to the nearest
  training view (coverage), over the unused candidates; the mean over seeds and view counts.

Every round length, sampler and M other than the first listed is paired with the first,
case by case (the same seed and view set, the other settings equal). Each case is written as
it finishes (`candidates/<case>.json`), so a killed run resumes.
"""

import itertools
import os
import time

import numpy as np

from mfsample import interrupts
from mfsample.config_blocks import data_spec
from mfsample.jobs import Budgets
from mfsample.quality.benchmark import parse_sampler
from mfsample.samplers import sample_z

# What a row varies; `paired` pairs each with its first value, the others held equal.
SETTINGS = ("round_steps", "sampler", "samples")


def farthest_views(pool, planning, seed, num_views):
  """The farthest-point strategy's first `num_views` views from the seed's initial view."""
  from mfsample.planning import runner, strategies

  cfg = planning.copy_and_resolve_references()
  with cfg.unlocked():
    cfg.max_views = int(num_views)
  selected, _ = runner.plan_views(strategies.make_strategy("farthest"), pool, cfg, seed,
                                  runner.Trainer(cfg, pool))
  return selected


def case_name(steps, sampler, seed, views):
  return f"steps{int(steps)}-{sampler.replace(':', '')}-seed{int(seed)}-views{int(views)}"


def candidates_pool(config):
  """The planning pool of `config.candidates.planning`, checked against the part's fields
  (before anything trains).

  Raises:
    ConfigError: a view count that leaves no unused candidate, or an image size the round
      models or the scoring cannot be made at (`planning.config.check_image_size`).
  """
  from mfsample.config_checks import ConfigError
  from mfsample.data import FILE_KINDS
  from mfsample.planning.config import check_image_size
  from mfsample.planning.pool import make_pool

  planning = config.candidates.planning.copy_and_resolve_references()
  with planning.unlocked():
    planning.data.progress = bool(config.progress) and bool(planning.data.progress)
  pool = make_pool(data_spec(planning.data))
  num, height, width = np.shape(pool.candidates.images)[:3]
  files = planning.data.path if planning.data.kind in FILE_KINDS else None
  if max(int(v) for v in config.candidates.views) >= num:
    raise ConfigError(f"config.candidates.views = {tuple(config.candidates.views)}: every "
                      f"count must leave unused candidates (< {num}, the candidates of "
                      + (f"the dataset at {files})" if files else "the pool)"))
  check_image_size(planning, width, height, files, prefix="config.candidates.planning")
  return pool


def run_candidates(config, wd, bar=None, pool=None):
  """Runs (or resumes) the candidates part of `config` in the workdir's `candidates/`
  (`wd`: a `mfsample.jobs.Workdir`; a missing or damaged case is computed again), on
  `pool` (default: `candidates_pool(config)`).

  Returns:
    {"scene", "seeds", "view_counts", "cases_per_row", "rows", "paired"}: a row per (round
    steps, sampler, M) with the means of rho(U, error), rho(U, angle), rho(error, angle) and
    the per-case rho(U, error) (seed-major); `paired` as in `paired_differences`.
  """
  from mfsample.planning import runner
  from mfsample.planning.u_error import u_against_error

  c = config.candidates
  planning = c.planning.copy_and_resolve_references()
  with planning.unlocked():
    planning.data.progress = bool(config.progress) and bool(planning.data.progress)
  pool = candidates_pool(config) if pool is None else pool
  counts = [int(v) for v in c.views]
  seeds = [int(s) for s in c.seeds]
  samples = [int(m) for m in c.samples]
  trajectories = {}
  cases = {}
  for steps, sampler in itertools.product((int(s) for s in c.steps), c.samplers):
    kind, rank = parse_sampler(sampler)
    cfg = planning.copy_and_resolve_references()
    with cfg.unlocked():
      cfg.rounds.steps = steps
      if rank is not None:
        cfg.round_train.sampler.rank = rank
    trainer = runner.Trainer(cfg, pool)
    budgets = Budgets()
    for seed, n in itertools.product(seeds, counts):
      entry = os.path.join("candidates", case_name(steps, sampler, seed, n) + ".json")
      record = wd.read_json(entry)
      if record is not None and not {str(m) for m in samples} <= set(record["by_samples"]):
        record = None  # an M asked for now was not measured then
      if record is None:
        interrupts.check(f"before {entry}")
        if bar is not None:
          bar.set_postfix_str(f"{steps} steps, {sampler}, seed {seed}, {n} views")
        if seed not in trajectories:
          trajectories[seed] = farthest_views(pool, planning, seed, max(counts))
        selected = trajectories[seed][:n]
        t0 = time.perf_counter()
        model, budgets = trainer.round_model(kind, selected, seed, budgets)
        train_seconds = time.perf_counter() - t0
        by_samples = {}
        used = [v.index for v in selected]
        unused = np.setdiff1d(np.arange(len(pool.candidates)), used)
        for m in samples:
          z = sample_z(model, m, seed=int(cfg.strategy.ours.z_seed))
          res = u_against_error(model, pool.candidates.cameras[unused], z,
                                background=pool.background,
                                images=np.asarray(pool.candidates.images)[unused],
                                train_cameras=pool.candidates.cameras[np.asarray(used)],
                                center=pool.sphere.center,
                                score_downscale=int(cfg.strategy.ours.score_downscale),
                                score_settings=budgets.get("score"),
                                mean_settings=budgets.get("mean"))
          budgets = budgets.replace(score=res.score_settings, mean=res.mean_settings)
          by_samples[str(m)] = {"rho_u_error": res.rho_u_error,
                                "rho_u_angle": res.rho_u_angle,
                                "rho_error_angle": res.rho_error_angle}
        record = {"round_steps": steps, "sampler": sampler, "seed": seed, "views": n,
                  "indices": [v.index for v in selected], "train_seconds": train_seconds,
                  "by_samples": by_samples}
        wd.write_json(entry, record)
      cases[(steps, sampler, seed, n)] = record
      if bar is not None:
        bar.update(1)
  rows = summarise(cases, c, seeds, counts, samples)
  return {"scene": pool.name, "seeds": seeds, "view_counts": counts,
          "cases_per_row": len(seeds) * len(counts), "rows": rows,
          "paired": [entry for field in SETTINGS for entry in paired_differences(rows, field)]}


def summarise(cases, c, seeds, counts, samples):
  """A row per (round steps, sampler, M): means over the cases (seed-major)."""
  rows = []
  for steps, sampler in itertools.product((int(s) for s in c.steps), c.samplers):
    records = [cases[(steps, sampler, seed, n)] for seed in seeds for n in counts]
    for m in samples:
      # An undefined rho (constant U or error) is null in the records: NaN here.
      values = np.asarray([[r["by_samples"][str(m)][k] for k in
                            ("rho_u_error", "rho_u_angle", "rho_error_angle")]
                           for r in records], dtype=float)
      rows.append({"round_steps": steps, "sampler": sampler, "samples": m,
                   "rho_u_error": float(values[:, 0].mean()),
                   "rho_u_angle": float(values[:, 1].mean()),
                   "rho_error_angle": float(values[:, 2].mean()),
                   "per_case_rho_u_error": values[:, 0].tolist(),
                   "round_train_seconds_median": float(np.median(
                       [r["train_seconds"] for r in records]))})
  return rows


def paired_differences(rows, field):
  """rho(U, error) of each value of `field` (round length, sampler or M) minus its first
  value in the rows, paired by case (the same seed and view set) with the other settings
  equal: mean, standard error and the number of cases above."""
  others = [f for f in SETTINGS if f != field]
  first = rows[0][field]
  base = {tuple(r[f] for f in others): np.asarray(r["per_case_rho_u_error"], dtype=float)
          for r in rows if r[field] == first}
  paired = []
  for r in rows:
    if r[field] == first:
      continue
    diff = np.asarray(r["per_case_rho_u_error"], dtype=float) - base[tuple(r[f] for f in others)]
    paired.append({**{f: r[f] for f in SETTINGS}, "minus": {field: first},
                   "mean": float(diff.mean()),
                   "sem": float(diff.std(ddof=1) / np.sqrt(len(diff))) if len(diff) > 1
                   else None,
                   "cases_above": int(np.sum(diff > 0)), "cases": len(diff)})
  return paired
