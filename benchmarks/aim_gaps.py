"""Where the planning aim stands, in one figure: the paired gaps at 10 views, protocol by protocol.

The issue's aim at 10 views: Ours (Sel.) above farthest point and above FisherRF, and
Ours (Opt. Sel.) at least as good as Ours (Sel.). Each planning experiment of
docs/camera_planning.md measures one of these differences under one protocol (round length,
round model, judge); this script reads them all back from their records under `results/`
(nothing here is typed in by hand: each gap is computed from a run's `results.json` or from
the rows of `benchmarks/final_training.py`), prints them as one table, and draws a forest
plot: per protocol the mean difference paired by seed with its standard error, the seeds
where the first strategy is better, and which of its seeds were fixed in advance.

  PYTHONPATH=. python benchmarks/aim_gaps.py

writes `results/aim_gaps.json` and `results/aim_gaps.png` (with matplotlib installed).
"""

import dataclasses
import json
import os

from absl import app, flags

from mfsample.planning import by_seeds, tables

_OUT = flags.DEFINE_string("out", "results/aim_gaps.json", "JSON output (the figure beside it).")
AIM_VIEWS = 10  # The aim is stated at 10 views (some records hold no other count).

SEL_FAR = ("ours_sel", "farthest")
SEL_FISHER = ("ours_sel", "fisher")
OPT_SEL = ("ours_opt_sel", "ours_sel")
OPT_BEST = ("ours_opt_best", "ours_sel")

COMPARISONS = {
    SEL_FAR: "Ours (Sel.) - Farthest Point",
    SEL_FISHER: "Ours (Sel.) - FisherRF",
    OPT_SEL: "Ours (Opt. Sel.) - Ours (Sel.)",
    OPT_BEST: "Ours (Opt. Best) - Ours (Sel.)",
}

# Judges of a view set: the run's own final models (600 steps), or re-judgings by
# final_training.py (one model from the run's seed, or the mean over its initialisations).
RUN = "600-step final"
FINAL_2000 = "2000-step final"
MEAN_OF_5 = "600-step finals, mean of {inits} inits"
DENSIFIED = "2000-step densified final"
DENSIFIED_MEAN = "2000-step densified finals, mean of {inits} inits"
DENSIFIED_200 = "3000-step densified final at 200 x 200"
FINAL_STEPS = {MEAN_OF_5: 600, FINAL_2000: 2000, DENSIFIED: 2000, DENSIFIED_MEAN: 2000,
               DENSIFIED_200: 3000}


@dataclasses.dataclass(frozen=True)
class Entry:
  """One measured difference: which strategies, on which record, under which protocol."""
  comparison: tuple
  scene: str
  protocol: str  # How the view sets were chosen.
  judge: str  # How they were judged.
  path: str
  # Which of its seeds had this outcome named before any of their runs (committed in their
  # config): "all", a range such as "seeds 16-23", or "" (measured, then reported).
  fixed_in_advance: str = ""

  @property
  def mean_over_inits(self):
    return self.judge in (MEAN_OF_5, DENSIFIED_MEAN)


def _entries():
  r = "results/"
  rounds400, rounds2000 = "400-step rounds", "2000-step rounds"
  authors = "2000-step rounds, authors' round models"
  fullres = "2000-step rounds at 80 x 80"
  out = []
  for comparison, runs in [
      (SEL_FAR, [("default", rounds400, "camera_planning_seeds8", ""),
                 ("default", rounds2000, "camera_planning_rounds2000_seeds24", "seeds 16-23"),
                 ("lego", rounds400, "camera_planning_lego_seeds8", ""),
                 ("lego", rounds2000, "camera_planning_lego_rounds2000_seeds16", "all"),
                 ("lego", authors, "camera_planning_lego_rounds2000_authors", "all"),
                 ("lego", fullres, "camera_planning_lego_rounds2000_fullres", "all")]),
      (SEL_FISHER, [("default", rounds400, "camera_planning_seeds8", ""),
                    ("default", rounds2000, "camera_planning_rounds2000", ""),
                    ("lego", rounds400, "camera_planning_lego_seeds8", ""),
                    ("lego", rounds2000, "camera_planning_lego_rounds2000_fisher", "all")]),
      (OPT_SEL, [("default", rounds400, "camera_planning_seeds8", ""),
                 ("default", rounds2000, "camera_planning_rounds2000_opt_sel_seeds24",
                  "seeds 16-23")]),
      (OPT_BEST, [("default", rounds2000, "camera_planning_rounds2000_seeds24", "seeds 16-23")]),
  ]:
    for scene, protocol, name, fixed in runs:
      out.append(Entry(comparison, scene, protocol, RUN, f"{r}{name}/results.json", fixed))
  for comparison, scene, protocol, judge, name, fixed in [
      (SEL_FAR, "default", rounds400, MEAN_OF_5, "final_inits_default", ""),
      (SEL_FAR, "default", rounds2000, FINAL_2000, "final_2000_rounds2000_seeds24", ""),
      (SEL_FAR, "lego", rounds400, MEAN_OF_5, "final_inits_lego", ""),
      (SEL_FAR, "lego", rounds2000, FINAL_2000, "final_2000_lego_rounds2000_seeds16", ""),
      (SEL_FAR, "lego", authors, FINAL_2000, "final_2000_lego_rounds2000_authors", ""),
      (SEL_FAR, "default", rounds2000, DENSIFIED, "final_2000_densified_default", "all"),
      (SEL_FAR, "default", rounds2000, DENSIFIED_MEAN, "final_2000_densified_default", "all"),
      (SEL_FAR, "lego", rounds2000, DENSIFIED, "final_2000_densified_lego", "all"),
      (SEL_FAR, "lego", rounds2000, DENSIFIED_MEAN, "final_2000_densified_lego", "all"),
      (SEL_FAR, "lego", rounds2000, DENSIFIED_200, "final_3000_gpu200_lego", "all"),
      (SEL_FISHER, "default", rounds400, MEAN_OF_5, "final_inits_default", ""),
      (SEL_FISHER, "default", rounds2000, FINAL_2000, "final_2000_rounds2000", ""),
      (SEL_FISHER, "lego", rounds400, MEAN_OF_5, "final_inits_lego", ""),
      (SEL_FISHER, "lego", rounds2000, FINAL_2000, "final_2000_lego_rounds2000_fisher", ""),
      (OPT_SEL, "default", rounds400, MEAN_OF_5, "final_inits_default", ""),
      (OPT_SEL, "default", rounds2000, FINAL_2000, "final_2000_rounds2000_opt_sel_seeds24", ""),
      (OPT_SEL, "default", rounds2000, DENSIFIED, "final_2000_densified_default", "all"),
      (OPT_SEL, "default", rounds2000, DENSIFIED_MEAN, "final_2000_densified_default", "all"),
      (OPT_BEST, "default", rounds2000, FINAL_2000, "final_2000_rounds2000_seeds24", ""),
      (OPT_BEST, "default", rounds2000, DENSIFIED, "final_2000_densified_default_opt_best",
       "all"),
  ]:
    out.append(Entry(comparison, scene, protocol, judge, f"{r}{name}.json", fixed))
  # Rows of one scene and protocol together, each judge in the order above.
  protocols = [rounds400, rounds2000, authors, fullres]
  judges = [RUN, MEAN_OF_5, FINAL_2000, DENSIFIED, DENSIFIED_MEAN, DENSIFIED_200]
  return sorted(out, key=lambda e: (list(COMPARISONS).index(e.comparison), e.scene,
                                    protocols.index(e.protocol), judges.index(e.judge)))


def _records(entry):
  if not os.path.exists(entry.path):
    raise FileNotFoundError(f"{entry.path} (the record of {entry.scene}, {entry.protocol}, "
                            f"{entry.judge}) does not exist")
  with open(entry.path) as f:
    data = json.load(f)
  if "runs" in data:
    return data["runs"]
  return by_seeds.records_from_final_rows(data["rows"], FINAL_STEPS[entry.judge],
                                          mean_over_inits=entry.mean_over_inits)


def gap(entry, views):
  """The entry's paired difference at `views`: {mean, sem, wins, seeds, values, judge} (the
  judge's name with the number of final models per view set)."""
  strategy, reference = entry.comparison
  records = _records(entry)
  paired = tables.paired_differences(records, [views], reference)
  if strategy not in paired or str(views) not in paired[strategy]:
    raise ValueError(f"{entry.path} has no seeds with both {strategy} and {reference} at "
                     f"{views} views")
  inits = {r.get("inits", 1) for r in records if r["strategy"] in entry.comparison}
  return {**paired[strategy][str(views)],
          "judge": entry.judge.format(inits="/".join(map(str, sorted(inits))))}


def _markdown(rows):
  lines = ["| Difference | Scene | Views chosen with | Judged by | Fixed in advance | "
           "ΔPSNR (dB) | better in |", "|---|---|---|---|---|---:|---:|"]
  for e, g in rows:
    lines.append(f"| {COMPARISONS[e.comparison]} | {e.scene} | {e.protocol} | {g['judge']} | "
                 f"{e.fixed_in_advance or '-'} | {g['mean']:+.2f} ± {g['sem']:.2f} | "
                 f"{g['wins']}/{len(g['seeds'])} |")
  return "\n".join(lines)


def _plot(rows, views, path):
  try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
  except ImportError:
    print("matplotlib not installed: no plot")
    return
  panels = [c for c in COMPARISONS if any(e.comparison == c for e, _ in rows)]
  heights = [sum(e.comparison == c for e, _ in rows) for c in panels]
  fig, axes = plt.subplots(len(panels), 1, figsize=(10.0, 0.36 * sum(heights) + 1.3 * len(panels)),
                           gridspec_kw={"height_ratios": heights}, squeeze=False)
  colours = {"default": "tab:blue", "lego": "tab:orange"}
  for ax, comparison in zip(axes[:, 0], panels, strict=True):
    mine = [(e, g) for e, g in rows if e.comparison == comparison]
    for y, (e, g) in enumerate(reversed(mine)):
      colour = colours.get(e.scene, "0.3")
      ax.errorbar(g["mean"], y, xerr=g["sem"], fmt="D" if e.fixed_in_advance else "o",
                  color=colour, capsize=3, ms=5,
                  mfc=colour if e.fixed_in_advance == "all" else "white")
      ax.annotate(f"{g['wins']}/{len(g['seeds'])}", (1.0, y), xycoords=("axes fraction", "data"),
                  xytext=(4, 0), textcoords="offset points", va="center", fontsize=7)
    ax.set_yticks(range(len(mine)))
    ax.set_yticklabels([f"{e.scene}: {e.protocol}; {g['judge']}" for e, g in reversed(mine)],
                       fontsize=7)
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_ylim(-0.6, len(mine) - 0.4)
    ax.set_title(f"{COMPARISONS[comparison]}, PSNR at {views} views", fontsize=9)
    ax.tick_params(axis="x", labelsize=7)
  axes[-1, 0].set_xlabel("paired difference, mean ± standard error over seeds (dB)\n"
                         "right: seeds where the first is better; diamonds: fixed in advance "
                         "(filled: all seeds, open: some)",
                         fontsize=7)
  fig.tight_layout()
  fig.savefig(path, dpi=120, bbox_inches="tight")  # The longest labels would touch the edge.
  plt.close(fig)
  print(f"wrote {path}")


def main(argv):
  del argv
  views = AIM_VIEWS
  rows = [(e, gap(e, views)) for e in _entries()]
  print(f"PSNR differences at {views} views, paired by seed, mean ± standard error:\n")
  print(_markdown(rows))
  with open(_OUT.value, "w") as f:
    json.dump({"views": views, "gaps": [
        {**dataclasses.asdict(e), "comparison": COMPARISONS[e.comparison], **g}
        for e, g in rows]}, f, indent=1)
  print(f"\nwrote {_OUT.value}")
  _plot(rows, views, os.path.splitext(_OUT.value)[0] + ".png")


if __name__ == "__main__":
  app.run(main)
