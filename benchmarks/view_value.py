"""What is the next view worth? Every candidate's measured value against each strategy's score.

The planning protocol judges a strategy by the final model trained on the views it chose.
This script measures, for one view set of a finished run, what each possible *next* view
is worth on that same scale: for every unused candidate c it trains the final model
(`config.final_train`, from scratch, the run's seed) on the view set plus c and evaluates
test PSNR, exactly as the protocol evaluates a strategy. Against those values it places
each strategy's score of the candidates, computed from the same view set and the same
round models as the protocol would:

- the value of each strategy's pick, and its rank among all candidates (1 = best);
- Spearman's rho of each strategy's scores against the values;
- the headroom: the best candidate's value, the median's, and the gap to each pick;
- where the views are: each pick's elevation, rho of each score and of the value with the
  candidates' elevation, and the elevations each strategy chose over the whole run
  against those of the test views;
- the winner's-curse check: the best few candidates and every pick trained again from
  another initialisation (`--repeat_top`, `--repeat_offset`).

Writes `--out` (JSON) and a figure beside it (`.png`): per case and strategy, every
candidate's value against the strategy's score percentile, the pick starred.

If the best next view is worth little more than the median one, no strategy can pull far
ahead at this scale; if it is worth much more and the picks miss it, the scores do.

The view sets (`--cases`) are the first views that `--prefix` chose in `--results` (the
check: the prefix strategy's own pick is the view its run took next). Resumable: rows
already in `--out` (same run, prefix, config) are kept and not recomputed. With no cases
(`--cases=`) it trains and writes nothing: it prints where each strategy of the run looked.

  PYTHONPATH=. python benchmarks/view_value.py --cases=0:9,1:9,0:4
"""

import json
import os
import time

from absl import app, flags
from ml_collections import config_flags

_CONFIG = config_flags.DEFINE_config_file(
    "config", "configs/camera_planning.py", "The planning config of the run.",
    lock_config=False)
_RESULTS = flags.DEFINE_string(
    "results", "results/camera_planning_seeds8/results.json", "results.json of the run.")
_PREFIX = flags.DEFINE_string("prefix", "ours_sel", "Strategy whose views form the view set.")
_CASES = flags.DEFINE_list(
    "cases", ["0:9", "1:9", "0:4"], "seed:size pairs: the first `size` views that the "
    "prefix strategy chose in the run of `seed` (the next view is view number size + 1).")
_STRATEGIES = flags.DEFINE_list("strategies", ["farthest", "fisher", "acp", "ours_sel"],
                                "Strategies whose scores are compared (selection only).")
_REPEAT_TOP = flags.DEFINE_integer(
    "repeat_top", 5, "The best this many candidates, and every pick, are trained again "
    "from another initialisation (seed + --repeat_offset): the winner's-curse check.")
_REPEAT_OFFSET = flags.DEFINE_integer("repeat_offset", 1000, "Seed offset of the repeats.")
_OUT = flags.DEFINE_string("out", "results/view_value.json", "JSON output (resumable).")


def _scores(names, config, pool, trainer, selected, seed, budgets):
  """{strategy: [C] scores} and {strategy: pick} on the view set `selected`."""
  import numpy as np

  from mfsample.planning import strategies
  from mfsample.planning.runner import choose_next

  available = np.ones(len(pool.candidates), bool)
  available[[s.index for s in selected]] = False
  scores, picks = {}, {}
  for name in names:
    strategy = strategies.make_strategy(name, config)
    if strategy.new_poses:
      raise ValueError(f"{name} proposes new poses; only selection strategies are scored.")
    # The round of `runner.plan_views`: the same round models, probes and draws.
    choice = choose_next(strategy, pool, config, seed, trainer, budgets, selected, available)
    scores[name] = np.where(available, np.asarray(choice.info["scores"], np.float64), np.nan)
    picks[name] = int(choice.index)
  return scores, picks


def _elevation_of_v(v):
  """Degrees above the horizontal plane through the scene centre (z up); v = polar angle / pi."""
  return 90.0 - 180.0 * v


def _elevation(cameras, center):
  """`_elevation_of_v` of each camera."""
  from mfsample.planning.poses import camera_to_uv

  return _elevation_of_v(camera_to_uv(cameras, center)[:, 1])


def _chosen_elevations(results, pool):
  """Where each strategy of the run looked, against where the test views are."""
  import numpy as np

  elev = _elevation(pool.candidates.cameras, pool.sphere.center)

  def stats(values):
    values = np.asarray(values, np.float64)
    return {"median": float(np.median(values)), "above_60": float(np.mean(values > 60)),
            "count": len(values)}

  out = {"candidates": stats(elev),
         "test": stats(_elevation(pool.test.cameras, pool.sphere.center))}
  for name in results["strategies"]:
    # Each record's uv (`runner.run_record`) covers the optimised poses too.
    chosen = [_elevation_of_v(v) for r in results["runs"] if r["strategy"] == name
              for _, v in r["uv"][1:]]
    if chosen:
      out[name] = stats(chosen)
    # The optimising strategies also record where each ascent started (`uv0`).
    starts = [_elevation_of_v(info["uv0"][1]) for r in results["runs"] if r["strategy"] == name
              for info in r["optimisation"][1:] if "uv0" in info]
    if starts:
      out[f"{name} (ascent starts)"] = stats(starts)
  return out


def _print_chosen_elevations(chosen):
  print("\nelevation (degrees) of the views each strategy chose in the run, all seeds:")
  for name, st in chosen.items():
    print(f"  {name}: median {st['median']:.0f}, above 60: {100 * st['above_60']:.0f}% "
          f"({st['count']} views)")


def _summary(case_rows, base_psnr, scores, picks):
  """Headroom, the picks' values and ranks, and rho of every score against the values."""
  import numpy as np
  from scipy.stats import spearmanr

  index = np.asarray([r["candidate"] for r in case_rows])
  value = np.asarray([r["psnr"] for r in case_rows], np.float64)
  order = np.argsort(-value)
  rank = {int(index[i]): int(r) + 1 for r, i in enumerate(order)}
  best, median = float(value.max()), float(np.median(value))
  out = {"candidates": len(value), "base_psnr": base_psnr,
         "best": {"candidate": int(index[order[0]]), "psnr": best},
         "median_psnr": median, "worst_psnr": float(value.min()),
         "std_psnr": float(value.std()), "strategies": {}}
  by_index = dict(zip(index.tolist(), value.tolist(), strict=True))
  for name, s in scores.items():
    pick = picks[name]
    rho = spearmanr(s[index], value).correlation
    out["strategies"][name] = {
        "pick": pick, "pick_psnr": by_index.get(pick), "pick_rank": rank.get(pick),
        "pick_minus_best": None if pick not in by_index else by_index[pick] - best,
        "pick_minus_median": None if pick not in by_index else by_index[pick] - median,
        "rho": float(rho)}
  return out


class _Values:
  """Trains and evaluates final models on view sets, and keeps every row (resumable)."""

  def __init__(self, config, pool, header, out):
    from mfsample._json import read_resumable_rows
    from mfsample.planning.runner import Trainer

    self.pool, self.header, self.out = pool, header, out
    self.trainer = Trainer(config, pool)
    self.rows = read_resumable_rows(out, header)
    self.done = {(r["seed"], r["views"], r["candidate"], r["train_seed"]) for r in self.rows}
    self.settings = None

  def psnr(self, selected, train_seed):
    """Test metrics of the final model trained on `selected` from `train_seed`."""
    from mfsample.planning.runner import evaluate_model

    model = self.trainer.final_model(selected, train_seed)
    metrics, self.settings = evaluate_model(
        model, self.pool.test, background=self.pool.background,
        settings=self.settings or self.trainer.settings["final"])
    return metrics

  def compute(self, seed, selected, todo, train_seed, desc):
    """A row per candidate in `todo` (None: the view set alone) not computed before."""
    from tqdm.auto import tqdm

    from mfsample._json import write_json
    from mfsample.planning.runner import candidate_view

    n = len(selected)
    for c in tqdm(todo, desc=desc):
      if (seed, n, c, train_seed) in self.done:
        continue
      extra = [] if c is None else [candidate_view(self.pool, c)]
      t0 = time.perf_counter()
      metrics = self.psnr(selected + extra, train_seed)
      self.rows.append({"seed": seed, "views": n, "candidate": c, "train_seed": train_seed,
                        "psnr": metrics["psnr"], "ssim": metrics["ssim"],
                        "seconds": time.perf_counter() - t0})
      self.done.add((seed, n, c, train_seed))
      write_json(self.out, {"header": self.header, "rows": self.rows}, indent=1)

  def of(self, seed, n, train_seed):
    return [r for r in self.rows
            if r["seed"] == seed and r["views"] == n and r["train_seed"] == train_seed]


def run():
  import numpy as np
  from scipy.stats import spearmanr

  from mfsample._json import write_json
  from mfsample.planning.pool import make_pool
  from mfsample.planning.runner import selected_from_record
  from mfsample.planning.workdirs import check_run_matches

  config = _CONFIG.value
  config.data.progress = False
  with open(_RESULTS.value) as f:
    results = json.load(f)
  names = list(_STRATEGIES.value)
  header = {"results": _RESULTS.value, "prefix": _PREFIX.value,
            "config": config_flags.get_config_filename(flags.FLAGS["config"]),
            "final_steps": int(config.final_train.train.num_steps),
            "round_steps": int(config.rounds.steps)}
  pool = make_pool(config.data)
  check_run_matches(pool, results)
  if not _CASES.value:
    _print_chosen_elevations(_chosen_elevations(results, pool))
    return
  values = _Values(config, pool, header, _OUT.value)
  budgets, cases = {}, []

  for case in _CASES.value:
    seed, n = (int(v) for v in case.split(":"))
    record = [r for r in results["runs"]
              if r["strategy"] == _PREFIX.value and int(r["seed"]) == seed]
    if not record:
      raise ValueError(f"{_RESULTS.value} has no {_PREFIX.value} run of seed {seed}.")
    selected = selected_from_record(record[0], pool)[:n]
    t0 = time.perf_counter()
    scores, picks = _scores(names, config, pool, values.trainer, selected, seed, budgets)
    score_seconds = time.perf_counter() - t0
    taken = record[0]["indices"][n] if n < len(record[0]["indices"]) else None
    if _PREFIX.value in picks and picks[_PREFIX.value] != taken:
      print(f"warning: seed {seed}, {n} views: {_PREFIX.value} picks {picks[_PREFIX.value]}"
            f" here, its run took {taken} (not the same protocol?)", flush=True)
    used = {s.index for s in selected}
    unused = [c for c in range(len(pool.candidates)) if c not in used]
    values.compute(seed, selected, [None] + unused, seed, f"seed {seed}, view {n + 1}")
    rows = values.of(seed, n, seed)
    base = [r for r in rows if r["candidate"] is None][0]["psnr"]
    case_rows = [r for r in rows if r["candidate"] is not None]
    ranked = sorted(case_rows, key=lambda r: -r["psnr"])
    repeat = [None] + [r["candidate"] for r in ranked[:_REPEAT_TOP.value]]
    repeat += [p for p in picks.values() if p not in repeat]
    again = seed + _REPEAT_OFFSET.value
    values.compute(seed, selected, repeat, again, f"seed {seed}, view {n + 1}, repeats")
    summary = _summary(case_rows, base, scores, picks)
    elev = _elevation(pool.candidates.cameras, pool.sphere.center)
    index = [r["candidate"] for r in case_rows]
    value = [r["psnr"] for r in case_rows]
    summary["elevation"] = {
        "rho_value": float(spearmanr(value, elev[index]).correlation),
        "rho_score": {k: float(spearmanr(v[index], elev[index]).correlation)
                      for k, v in scores.items()},
        "pick": {k: float(elev[p]) for k, p in picks.items()}}
    summary["repeat"] = {"train_seed": again, "psnr": {
        str(r["candidate"]): r["psnr"] for r in values.of(seed, n, again)}}
    summary.update(seed=seed, views=n, taken_by_prefix_run=taken,
                   score_seconds=score_seconds,
                   scores={k: [None if np.isnan(x) else float(x) for x in v]
                           for k, v in scores.items()})
    cases.append(summary)
    _print_case(summary)
  chosen = _chosen_elevations(results, pool)
  _print_chosen_elevations(chosen)
  seconds = [r["seconds"] for r in values.rows]
  print(f"\n{len(seconds)} final models in the file, {sum(seconds):.0f} s of training and "
        f"evaluation as recorded per row ({np.mean(seconds):.0f} s each)")
  write_json(_OUT.value, {"header": header, "rows": values.rows, "cases": cases,
                          "chosen_elevation": chosen}, indent=1)
  print(f"wrote {_OUT.value}")
  _plot(cases, values.rows, os.path.splitext(_OUT.value)[0] + ".png")


def _plot(cases, rows, path):
  """Per case and strategy: each candidate's value against how the strategy ranks it."""
  try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
  except ImportError:
    print("matplotlib not installed: no plot")
    return
  import numpy as np
  from scipy.stats import rankdata

  names = list(cases[0]["strategies"])
  fig, axes = plt.subplots(len(cases), len(names), figsize=(3.2 * len(names), 2.8 * len(cases)),
                           squeeze=False, sharey="row")
  for row, case in zip(axes, cases, strict=True):
    mine = [r for r in rows if r["seed"] == case["seed"] and r["views"] == case["views"]
            and r["train_seed"] == case["seed"] and r["candidate"] is not None]
    index = np.asarray([r["candidate"] for r in mine])
    gain = np.asarray([r["psnr"] for r in mine]) - case["base_psnr"]
    for ax, name in zip(row, names, strict=True):
      score = np.asarray(case["scores"][name], np.float64)[index]
      percentile = (rankdata(score) - 1) / max(len(score) - 1, 1)  # 1: the strategy's top
      ax.scatter(percentile, gain, s=10, color="0.4")
      pick = case["strategies"][name]["pick"]
      at = np.flatnonzero(index == pick)
      ax.scatter(percentile[at], gain[at], s=90, marker="*", color="tab:red", label="pick")
      ax.axhline(0.0, color="k", lw=0.8)
      ax.axhline(np.median(gain), color="tab:blue", lw=0.8, ls="--", label="median")
      ax.set_title(f"{name}, rho {case['strategies'][name]['rho']:+.2f}", fontsize=9)
      ax.set_xlabel("score percentile among candidates", fontsize=8)
    row[0].set_ylabel(f"seed {case['seed']}, view {case['views'] + 1}:\n"
                      "PSNR gain over the view set (dB)", fontsize=8)
  axes[0][0].legend(fontsize=7)
  fig.tight_layout()
  fig.savefig(path, dpi=110)
  plt.close(fig)
  print(f"wrote {path}")


def _print_case(s):
  print(f"\nseed {s['seed']}, choosing view {s['views'] + 1} ({s['candidates']} candidates; "
        f"the {s['views']} views alone: {s['base_psnr']:.2f} dB): best {s['best']['psnr']:.2f}"
        f" (candidate {s['best']['candidate']}), median {s['median_psnr']:.2f}, worst "
        f"{s['worst_psnr']:.2f}")
  print("| strategy | pick | PSNR | rank | - best | - median | rho(score, value) |")
  print("|---|---|---|---|---|---|---|")
  for name, v in s["strategies"].items():
    print(f"| {name} | {v['pick']} | {v['pick_psnr']:.2f} | {v['pick_rank']} | "
          f"{v['pick_minus_best']:+.2f} | {v['pick_minus_median']:+.2f} | {v['rho']:+.2f} |",
          flush=True)
  e = s["elevation"]
  print("elevation of the picks: " + ", ".join(f"{k} {v:.0f}" for k, v in e["pick"].items())
        + "; rho(score, elevation): " + ", ".join(f"{k} {v:+.2f}"
                                                  for k, v in e["rho_score"].items())
        + f"; rho(value, elevation) {e['rho_value']:+.2f}")
  rep = s["repeat"]["psnr"]
  if rep:
    best = str(s["best"]["candidate"])
    parts = [f"{name} {rep[str(v['pick'])]:.2f}" for name, v in s["strategies"].items()
             if str(v["pick"]) in rep]
    print(f"again from initialisation {s['repeat']['train_seed']}: the {s['views']} views "
          f"alone {rep.get('None', float('nan')):.2f}, the best above "
          f"{rep.get(best, float('nan')):.2f}; picks: {', '.join(parts)}", flush=True)


def main(argv):
  del argv
  run()


if __name__ == "__main__":
  app.run(main)
