"""Tables of the uncertainty-quality experiment, from its records (markdown).

* `ause_summary`: per method and scene, AUSE averaged over the test views and seeds (MAE and
  RMSE), and per model the context: test PSNR, depth MAE, masked fraction, a constant map's
  AUSE (no information).
* `ause_markdown`: the paper's Table 5 layout (methods down, scenes across, then the mean over
  scenes), for MAE and RMSE, and the context table.
* `candidates_markdown`: rho(U, error) per round length, sampler and M, the paired
  differences, and rho(U, error) per seed.
"""

import numpy as np

from mfsample.quality.benchmark import DETERMINISTIC, parse_sampler
from mfsample.samplers import KINDS

BASELINE_LABELS = {"fisher": "FisherRF", "activenerf": "ActiveNeRF",
                   "posthoc_colour": "Post-hoc B_hat: U (Eq. 10)",
                   "posthoc_depth": "Post-hoc B_hat: depth variance"}
MAP_LABELS = {"colour": "U (Eq. 10)", "depth": "depth variance"}


def model_label(name):
  """"lowrank:2" -> "Ours, rank 2", "diagonal" -> "Diagonal", "block:2" -> "Block, rank 2"
  (the kind's label, and its rank where its B_hat has a rank axis)."""
  if name == DETERMINISTIC:
    return KINDS[DETERMINISTIC].label
  kind, rank = parse_sampler(name)
  behaviour = KINDS[kind]
  if not behaviour.rank_axis:
    return behaviour.label
  return f"{behaviour.label}, rank {rank if rank is not None else '(config)'}"


def method_label(model, method):
  if model == DETERMINISTIC:
    return BASELINE_LABELS.get(method, method)
  return f"{model_label(model)}: {MAP_LABELS.get(method, method)}"


def _mean(values):
  values = [v for v in values if v is not None]
  return float(np.mean(values)) if values else None


def ause_summary(records, scenes):
  """{"methods": [(model, method)], "ause": {measure: {"model/method": {scene: mean,
  "mean": over scenes}}}, "context": {model: {field: {scene: mean, "mean": ...}}}}."""
  order = []
  for r in records:
    for method in r["methods"]:
      if (r["model"], method) not in order:
        order.append((r["model"], method))
  # FisherRF and ActiveNeRF first, as in the paper's table; then Ours' colour U, then depth.
  order.sort(key=lambda mm: (mm[0] != DETERMINISTIC, mm[1] == "depth"))
  out = {"methods": [f"{m}/{k}" for m, k in order], "ause": {}, "context": {}}
  for measure in ("mae", "rmse"):
    table = {}
    for model, method in order + [(r["model"], "constant") for r in records]:
      key = f"{model}/{method}"
      row = {}
      for scene in scenes:
        values = [v["ause"].get(method, {}).get(measure) for r in records
                  if r["model"] == model and r["scene"] == scene for v in r["views"]]
        row[scene] = _mean(values)
      row["mean"] = _mean([row[s] for s in scenes])
      table[key] = row
    out["ause"][measure] = table
  for model in dict.fromkeys(r["model"] for r in records):
    context = {}
    for field in ("psnr", "depth_mae", "mask_fraction"):
      row = {scene: _mean([v[field] for r in records if r["model"] == model
                           and r["scene"] == scene for v in r["views"]]) for scene in scenes}
      row["mean"] = _mean([row[s] for s in scenes])
      context[field] = row
    context["constant_ause"] = out["ause"]["mae"][f"{model}/constant"]
    context["train_seconds"] = _mean([r["train_seconds"] for r in records
                                      if r["model"] == model])
    fits = [r["posthoc"] for r in records if r["model"] == model and "posthoc" in r]
    if fits:  # the post-hoc fits of the deterministic model
      context["posthoc"] = {"sampler": fits[0]["sampler"],
                            "steps": sorted({f["steps"] for f in fits}),
                            "seconds": _mean([f["seconds"] for f in fits]),
                            "mean_unchanged": all(f["mean_unchanged"] for f in fits)}
    out["context"][model] = context
  return out


def _fmt(v, digits=3):
  return "-" if v is None else f"{v:.{digits}f}"


def ause_markdown(summary, scenes, title):
  """The Table 5 layout for MAE and RMSE, then the context table."""
  header = "| Method | " + " | ".join(scenes) + " | Avg. |"
  rule = "|---|" + "---:|" * (len(scenes) + 1)
  lines = [title, ""]
  for measure, name in (("mae", "AUSE of the depth MAE (the paper's Table 5)"),
                        ("rmse", "AUSE of the depth RMSE")):
    lines += [f"{name}, lower is better:", "", header, rule]
    for key in summary["methods"]:
      model, method = key.split("/")
      row = summary["ause"][measure][key]
      lines.append(f"| {method_label(model, method)} | "
                   + " | ".join(_fmt(row[s]) for s in scenes) + f" | {_fmt(row['mean'])} |")
    lines.append("")
  lines += ["Each model on the test views: PSNR of the mean render, depth MAE and fraction of "
            "the pixels where the error counts, and the AUSE (MAE) of a constant map (a random "
            "ranking's expectation: no information).", "",
            "| Model | PSNR | depth MAE | pixels counted | constant map AUSE | training s |",
            "|---|---:|---:|---:|---:|---:|"]
  for model, ctx in summary["context"].items():
    lines.append(f"| {model_label(model)} | {_fmt(ctx['psnr']['mean'], 2)} | "
                 f"{_fmt(ctx['depth_mae']['mean'], 3)} | "
                 f"{_fmt(ctx['mask_fraction']['mean'], 2)} | "
                 f"{_fmt(ctx['constant_ause']['mean'])} | {_fmt(ctx['train_seconds'], 0)} |")
  for model, ctx in summary["context"].items():
    if "posthoc" in ctx:
      p = ctx["posthoc"]
      lines += ["", f"Post-hoc B_hat ({p['sampler']}) fitted to the {model_label(model).lower()} "
                f"model with its mean frozen: {', '.join(map(str, p['steps']))} steps, "
                f"{_fmt(p['seconds'], 1)} s per model (mean, compilation included); mean "
                f"{'unchanged, bit for bit' if p['mean_unchanged'] else 'CHANGED'}."]
  return "\n".join(lines) + "\n"


def candidates_markdown(result, title):
  """rho(U, error) per (round steps, sampler, M), the paired differences, and per seed."""
  lines = [title, "",
           f"Means over {result['cases_per_row']} cases (seeds {result['seeds']} x view "
           f"counts {result['view_counts']}).", "",
           "| round steps | sampler | M | rho(U, error) | rho(U, angle) | rho(error, angle) | "
           "round model s |", "|---:|---|---:|---:|---:|---:|---:|"]
  for r in result["rows"]:
    lines.append(f"| {r['round_steps']} | {r['sampler']} | {r['samples']} | "
                 f"{r['rho_u_error']:.2f} | {r['rho_u_angle']:.2f} | "
                 f"{r['rho_error_angle']:.2f} | {r['round_train_seconds_median']:.1f} |")
  if result["paired"]:
    lines += ["", "Paired by case, rho(U, error) minus that of the first value, mean ± "
              "standard error (cases above):", "",
              "| round steps | sampler | M | minus | difference |", "|---:|---|---:|---|---:|"]
    for p in result["paired"]:
      (field, first), = p["minus"].items()
      sem = "" if p["sem"] is None else f" ± {p['sem']:.2f}"
      lines.append(f"| {p['round_steps']} | {p['sampler']} | {p['samples']} | "
                   f"{field} {first} | {p['mean']:+.2f}{sem} "
                   f"({p['cases_above']}/{p['cases']}) |")
  seeds = result["seeds"]
  lines += ["", "rho(U, error) per seed (mean over its view counts):", "",
            "| round steps | sampler | M | " + " | ".join(f"seed {s}" for s in seeds) + " |",
            "|---:|---|---:|" + "---:|" * len(seeds)]
  for r in result["rows"]:
    per_seed = np.asarray(r["per_case_rho_u_error"]).reshape(len(seeds), -1).mean(axis=1)
    lines.append(f"| {r['round_steps']} | {r['sampler']} | {r['samples']} | "
                 + " | ".join(f"{v:+.2f}" for v in per_seed) + " |")
  return "\n".join(lines) + "\n"
