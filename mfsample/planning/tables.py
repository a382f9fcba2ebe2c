"""The planning protocol's tables: Table 1 (mean ± std over seeds), differences paired by
seed, the view optimisation's rounds and the wall-clock, as dicts and as markdown.

Pure functions of run records (`runner.run_record`); `report_markdown` assembles the
runner's `table.md` from them. Each (strategy, seed) run counts once (`unique_runs`): a
record listed twice must not weigh twice in a mean or a standard error.
"""

import json

import numpy as np

from mfsample.planning import strategies

METRICS = (("psnr", "PSNR", "↑"), ("ssim", "SSIM", "↑"), ("lpips", "LPIPS", "↓"))
_DIGITS = {"psnr": 2, "ssim": 3, "lpips": 3}  # Decimals of each metric in the tables.


def unique_runs(records):
  """`records` with each (strategy, seed) once, in order of first appearance (records
  without a seed cannot be matched and are all kept).

  Raises:
    ValueError: two different records of one (strategy, seed) (mixed runs).
  """
  seen, out = {}, []
  for rec in records:
    if "seed" not in rec:
      out.append(rec)
      continue
    key = (rec["strategy"], int(rec["seed"]))
    if key not in seen:
      seen[key] = rec
      out.append(rec)
    elif json.dumps(seen[key], sort_keys=True) != json.dumps(rec, sort_keys=True):
      raise ValueError(f"two different records of strategy {key[0]!r}, seed {key[1]}: "
                       "a table counts each run once")
  return out


def summarise(records, eval_views):
  """{strategy: {n: {metric: {"mean", "std", "values"}}}} over seeds (std: population)."""
  out = {}
  for rec in unique_runs(records):
    s = out.setdefault(rec["strategy"], {"label": rec["label"]})
    for n in eval_views:
      m = rec["metrics"].get(str(n))
      if m is None:
        continue
      for name, _, _ in METRICS:
        if m.get(name) is None:
          continue
        s.setdefault(str(n), {}).setdefault(name, {"values": []})["values"].append(m[name])
  for s in out.values():
    for n in eval_views:
      for entry in s.get(str(n), {}).values():
        v = np.asarray(entry["values"], np.float64)
        entry["mean"], entry["std"] = float(v.mean()), float(v.std())
  return out


def _in_order(keyed, order):
  """The keys of `keyed`: those in `order` first, in its order, then the rest as they come."""
  return [n for n in order if n in keyed] + [n for n in keyed if n not in order]


def table_markdown(summary, eval_views, order=strategies.NAMES, title=None):
  """The paper's Table 1 layout: strategies x (PSNR, SSIM, LPIPS) at each view count."""
  head = ["Method"] + [f"{label}{arrow} ({n} views)" for n in eval_views
                       for _, label, arrow in METRICS]
  lines = [] if title is None else [title, ""]
  lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
  for name in _in_order(summary, order):
    s = summary[name]
    row = [s["label"]]
    for n in eval_views:
      for metric, _, _ in METRICS:
        e = s.get(str(n), {}).get(metric)
        d = _DIGITS[metric]
        row.append("-" if e is None else f"{e['mean']:.{d}f} ± {e['std']:.{d}f}")
    lines.append("| " + " | ".join(row) + " |")
  return "\n".join(lines) + "\n"


def paired_differences(records, eval_views, reference, metric="psnr"):
  """Per-seed differences of every strategy to `reference`, over the seeds both ran.

  The strategies of one seed share the initial view and the random initialisation, so the
  seed-to-seed spread that the std of `summarise` carries largely cancels in a difference:
  a gap of 0.1 dB can be clear when paired and invisible in mean ± std.

  Returns:
    {strategy: {n: {"mean", "sem" (standard error; None for one seed), "wins" (seeds where
    the strategy is better: higher for PSNR / SSIM, lower for LPIPS), "seeds", "values"}}}.
  """
  higher_is_better = dict((m, arrow == "↑") for m, _, arrow in METRICS)[metric]
  records = unique_runs(records)
  by_run = {(rec["strategy"], rec["seed"]): rec["metrics"] for rec in records}
  out = {}
  for name in dict.fromkeys(rec["strategy"] for rec in records):
    if name == reference:
      continue
    for n in eval_views:
      key = str(n)
      seeds = sorted(seed for (s, seed) in by_run if s == name and (reference, seed) in by_run
                     and by_run[(name, seed)].get(key, {}).get(metric) is not None
                     and by_run[(reference, seed)].get(key, {}).get(metric) is not None)
      if not seeds:
        continue
      d = np.asarray([by_run[(name, seed)][key][metric] - by_run[(reference, seed)][key][metric]
                      for seed in seeds], np.float64)
      better = d > 0 if higher_is_better else d < 0
      out.setdefault(name, {})[key] = {
          "mean": float(d.mean()),
          "sem": float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else None,
          "wins": int(better.sum()), "seeds": seeds, "values": d.tolist()}
  return out


def paired_markdown(paired, labels, reference_label, eval_views, metric="psnr",
                    order=strategies.NAMES):
  """Mean paired difference ± standard error, and the seeds won, per strategy and view count."""
  label = dict((m, lab) for m, lab, _ in METRICS)[metric]
  head = ["Method"] + [f"Δ{label} vs {reference_label} ({n} views)" for n in eval_views]
  lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
  digits = _DIGITS[metric]
  for name in _in_order(paired, order):
    row = [labels[name]]
    for n in eval_views:
      e = paired[name].get(str(n))
      if e is None:
        row.append("-")
        continue
      sem = "" if e["sem"] is None else f" ± {e['sem']:.{digits}f}"
      row.append(f"{e['mean']:+.{digits}f}{sem} (better in {e['wins']}/{len(e['seeds'])})")
    lines.append("| " + " | ".join(row) + " |")
  return "\n".join(lines) + "\n"


def optimisation_summary(records):
  """How the camera ascent went, per optimising strategy, over all its rounds.

  Returns {strategy: {"rounds", "u_rose" (rounds where U at the ascent's end, as the ascent
  measures it: M = optimize.samples at its image size, beat U at its start),
  "u_end_over_start" (mean ratio), and for Ours (Opt. Best) "kept_moved" (rounds that kept a
  visited pose, not the start), "kept_steps" ({ascent step kept (0: the start): rounds}) and
  "kept_over_start" (mean ratio of U as selection measures it, kept pose over start; >= 1)}}.
  Strategies without an ascent are left out.
  """
  out = {}
  for rec in unique_runs(records):
    rounds = [o for o in rec.get("optimisation", []) if o and "u_start" in o]
    if not rounds:
      continue
    e = out.setdefault(rec["strategy"], {"rounds": 0, "u_rose": 0, "_ratios": []})
    e["rounds"] += len(rounds)
    e["u_rose"] += sum(o["u_end"] > o["u_start"] for o in rounds)
    e["_ratios"] += [o["u_end"] / o["u_start"] for o in rounds]
    kept = [o for o in rounds if "kept_step" in o]
    if kept:
      e["kept_moved"] = e.get("kept_moved", 0) + sum(o["kept_step"] > 0 for o in kept)
      steps = e.setdefault("kept_steps", {})
      for o in kept:
        steps[str(o["kept_step"])] = steps.get(str(o["kept_step"]), 0) + 1
      e.setdefault("_kept", []).extend(
          max(o["start_score"], *o["u_visited"]) / o["start_score"] for o in kept)
  for e in out.values():
    e["u_end_over_start"] = float(np.mean(e.pop("_ratios")))
    if "_kept" in e:
      e["kept_over_start"] = float(np.mean(e.pop("_kept")))
  return out


def optimisation_markdown(summary, labels, order=strategies.NAMES):
  """`optimisation_summary` as a markdown table."""
  lines = ["| Method | rounds | ascent raised its U | its U, end / start (mean) | kept a "
           "visited pose | selection's U, kept / start (mean) |", "|---|---:|---:|---:|---:|---:|"]
  for name in [n for n in order if n in summary]:
    e = summary[name]
    kept = (f"{e['kept_moved']} | {e['kept_over_start']:.3f}" if "kept_moved" in e
            else "- | -")
    lines.append(f"| {labels[name]} | {e['rounds']} | {e['u_rose']} | "
                 f"{e['u_end_over_start']:.3f} | {kept} |")
  return "\n".join(lines) + "\n"


def seconds_summary(records):
  """Wall-clock per run and per round, per strategy, as the run records hold them.

  Returns {strategy: {"runs", "run": {"min", "median", "max"}, "round": {...}}}: "run" is a
  run's `seconds` (its rounds, captures and final models), "round" every round after the
  first (round 0 is the initial view, chosen without training). Recorded times include
  whatever else the machine ran meanwhile.
  """
  runs, rounds = {}, {}
  for rec in unique_runs(records):
    runs.setdefault(rec["strategy"], []).append(rec["seconds"])
    rounds.setdefault(rec["strategy"], []).extend(rec["round_seconds"][1:])

  def spread(values):
    v = np.asarray(values, np.float64)
    return {"min": float(v.min()), "median": float(np.median(v)), "max": float(v.max())}

  return {name: {"runs": len(values), "run": spread(values),
                 **({"round": spread(rounds[name])} if rounds[name] else {})}
          for name, values in runs.items()}


def seconds_markdown(summary, labels, order=strategies.NAMES):
  """`seconds_summary` as a markdown table (min / median / max, seconds)."""
  def cell(e):
    return f"{e['min']:.0f} / {e['median']:.0f} / {e['max']:.0f}"

  lines = ["| Method | runs | seconds per run (min / median / max) | seconds per round "
           "after the first (min / median / max) |", "|---|---:|---:|---:|"]
  for name in _in_order(summary, order):
    e = summary[name]
    round_cell = cell(e["round"]) if "round" in e else "-"
    lines.append(f"| {labels[name]} | {e['runs']} | {cell(e['run'])} | {round_cell} |")
  return "\n".join(lines) + "\n"


def report_markdown(summary, paired, optimisation, run_seconds, labels, eval_views, title):
  """`table.md`: Table 1, the paired differences (when there are several seeds), the
  camera ascent of the optimising strategies and the wall-clock of the runs."""
  text = table_markdown(summary, eval_views, title=title)
  for reference, diffs in paired.items():
    text += (f"\nPaired by seed (same initial view and initialisation), PSNR minus "
             f"{labels[reference]}'s, mean ± standard error:\n\n")
    text += paired_markdown(diffs, labels, labels[reference], eval_views)
  if optimisation:
    text += ("\nThe camera ascent of the optimising strategies, over all rounds and seeds "
             "(its U: M = strategy.optimize.samples at its image size; selection's U: as "
             "candidates are scored):\n\n" + optimisation_markdown(optimisation, labels))
  text += ("\nWall-clock of the runs, as each run recorded it (a round whose model another "
           "run of the same seed trained earlier in the call, such as the one-view model "
           "the \"Ours\" variants share, comes from the trainer's cache):\n\n"
           + seconds_markdown(run_seconds, labels))
  return text
