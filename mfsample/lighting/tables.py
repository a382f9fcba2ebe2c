"""The light-planning tables: metrics against the number of lights, and a summary at L lights.

Pure functions of the protocol's records (`protocol.run_light_planning`).
"""

import numpy as np

from mfsample.lighting import strategies

METRICS = (("psnr", "PSNR", "↑", 2), ("ssim", "SSIM", "↑", 3), ("lpips", "LPIPS", "↓", 3))


def summarise(shared, records):
  """{strategy: {"label", "by_lights": {l: metrics}, "u_ratio": [...], "plan_seconds": [...],
  "train_seconds": [...]}}; l = 1 is the shared first phase, the same for every strategy."""
  out = {}
  for rec in records:
    by_lights = {"1": shared["metrics"]}
    for phase in rec["phases"]:
      by_lights[str(phase["lights"])] = phase["metrics"]
    out[rec["strategy"]] = {
        "label": rec["label"], "by_lights": by_lights,
        "u_ratio": [p["u_ratio"] for p in rec["phases"]],
        "plan_seconds": [p["plan_seconds"] for p in rec["phases"]],
        "train_seconds": [shared["train_seconds"]] + [p["train_seconds"] for p in rec["phases"]],
    }
  return out


def _fmt(value, digits):
  return "-" if value is None else f"{value:.{digits}f}"


def _in_order(summary):
  return [n for n in strategies.NAMES if n in summary] + [n for n in summary
                                                           if n not in strategies.NAMES]


def by_lights_markdown(summary, total, metric="psnr"):
  """One row per strategy, one column per number of lights (1..total)."""
  label, arrow, digits = {m: (lab, a, d) for m, lab, a, d in METRICS}[metric]
  head = ["Method"] + [f"{label}{arrow} {n} light{'s' if n > 1 else ''}"
                       for n in range(1, total + 1)]
  lines = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * total]
  for name in _in_order(summary):
    s = summary[name]
    row = [s["label"]] + [_fmt(s["by_lights"].get(str(n), {}).get(metric), digits)
                          for n in range(1, total + 1)]
    lines.append("| " + " | ".join(row) + " |")
  return "\n".join(lines) + "\n"


def final_markdown(summary, total):
  """At `total` lights: every metric, PSNR per kind of test light, U of the chosen lights
  relative to the best on the sphere, and planning seconds per light."""
  kinds = []
  for s in summary.values():
    for kind in s["by_lights"].get(str(total), {}).get("by_kind", {}):
      if kind not in kinds:
        kinds.append(kind)
  head = (["Method"] + [f"{lab}{a}" for _, lab, a, _ in METRICS]
          + [f"PSNR↑ {k} lights" for k in kinds]
          + ["U / max U of the chosen lights", "planning s / light"])
  lines = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 1)]
  for name in _in_order(summary):
    s = summary[name]
    m = s["by_lights"].get(str(total), {})
    ratios = [r for r in s["u_ratio"] if r is not None]
    row = [s["label"]] + [_fmt(m.get(k), d) for k, _, _, d in METRICS]
    row += [_fmt(m.get("by_kind", {}).get(k, {}).get("psnr"), 2) for k in kinds]
    row += [_fmt(float(np.mean(ratios)) if ratios else None, 3),
            _fmt(float(np.mean(s["plan_seconds"])) if s["plan_seconds"] else None, 1)]
    lines.append("| " + " | ".join(row) + " |")
  return "\n".join(lines) + "\n"


def report_markdown(summary, total, title):
  """`table.md`: PSNR, SSIM and LPIPS against the number of lights, then the summary."""
  parts = [title, ""]
  for metric, label, _, _ in METRICS:
    if any(s["by_lights"].get("1", {}).get(metric) is not None for s in summary.values()):
      parts += [f"{label} of relit test views against the number of lights:", "",
                by_lights_markdown(summary, total, metric)]
  parts += [f"At {total} lights (U / max U: U of each chosen light over the largest U on the "
            "sphere under the model that chose it, mean over the chosen lights):", "",
            final_markdown(summary, total)]
  return "\n".join(parts)
