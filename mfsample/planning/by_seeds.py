"""Reports of a part of a planning run's seeds.

The runner's `table.md` covers all the seeds of a workdir. When seeds were added by a later
call (a pre-registered one names its outcomes over the new seeds and over all of them), or
the machine was slower for some, a range of seeds at a time says more. These build the
runner's tables (`tables.seconds_markdown`, `tables.paired_markdown`) per range `a:b`
(seeds a .. b-1), from a run's records or from the rows that `benchmarks/final_training.py`
writes.
"""

import numpy as np

from mfsample.planning import tables


def seed_range(text):
  """'a:b' -> range(a, b), with a clear error for anything else."""
  try:
    first, end = (int(part) for part in text.split(":"))
  except ValueError:
    raise ValueError(f"a seed range is 'a:b' (seeds a .. b-1), got {text!r}") from None
  if end <= first:
    raise ValueError(f"seed range {text!r} is empty")
  return range(first, end)


def _title(seeds):
  return f"Seed {seeds.start}" if len(seeds) == 1 else f"Seeds {seeds.start}-{seeds.stop - 1}"


def _labels(records):
  return {r["strategy"]: r["label"] for r in records}  # As the runner labels its tables.


def seconds_tables(records, ranges, names=()):
  """Markdown: one `tables.seconds_markdown` table per seed range (of the runs it holds)."""
  labels = _labels(records)
  out = []
  for seeds in ranges:
    chosen = [r for r in records if r["seed"] in seeds and (not names or r["strategy"] in names)]
    if not chosen:
      out.append(f"{_title(seeds)}: no runs.\n")
      continue
    out.append(f"{_title(seeds)}:\n\n"
               + tables.seconds_markdown(tables.seconds_summary(chosen), labels))
  return "\n".join(out)


def tagged(records, tag):
  """The records of another run, renamed `strategy@tag` / `Label [tag]`, so that they can be
  paired by seed with a run of the same strategies (two protocols with the same seeds share
  the initial view and the random initialisation)."""
  if not tag or "@" in tag:
    raise ValueError(f"a run's tag is a non-empty name without '@', got {tag!r}")
  return [{**r, "strategy": f"{r['strategy']}@{tag}", "label": f"{r['label']} [{tag}]"}
          for r in records]


def paired_tables(records, ranges, references, views, metric="psnr", per_seed=False):
  """Markdown: per seed range and reference, the paired differences of the others to it
  (with `per_seed`, each seed's difference too)."""
  labels = _labels(records)
  out = []
  for seeds in ranges:
    chosen = [r for r in records if r["seed"] in seeds]
    for reference in references:
      paired = tables.paired_differences(chosen, views, reference, metric)
      if not paired:
        out.append(f"{_title(seeds)}: no seeds with {reference} and another strategy.\n")
        continue
      out.append(f"{_title(seeds)}, paired with {labels[reference]} (mean ± standard error):"
                 "\n\n" + tables.paired_markdown(paired, labels, labels[reference], views,
                                                 metric))
      if per_seed:
        out.append(_per_seed_markdown(paired, labels, labels[reference], views, metric))
  return "\n".join(out)


def _per_seed_markdown(paired, labels, reference_label, views, metric):
  """One row per strategy and view count: its difference to the reference, seed by seed."""
  seeds = sorted({s for by_n in paired.values() for e in by_n.values() for s in e["seeds"]})
  head = ["Method", "views"] + [f"seed {s}" for s in seeds]
  label = dict((m, lab) for m, lab, _ in tables.METRICS)[metric]
  lines = [f"Per seed, Δ{label} vs {reference_label}:", "",
           "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
  for name, by_n in paired.items():
    for n in views:
      e = by_n.get(str(n))
      if e is None:
        continue
      value = dict(zip(e["seeds"], e["values"], strict=True))
      lines.append("| " + " | ".join([labels[name], str(n)] + [
          f"{value[s]:+.3f}" if s in value else "-" for s in seeds]) + " |")
  return "\n".join(lines) + "\n"


def records_from_final_rows(rows, steps=None, mean_over_inits=False):
  """Run-style records ({strategy, label, seed, inits, metrics: {n: {psnr, ssim}}}) from the rows of
  final_training.py at `steps` (None: the one length the rows hold), one model per view set:
  the one trained from the run's own seed, as the protocol trains it. With
  `mean_over_inits`, each view set's metrics are the mean over all its models (its
  initialisations); every view set must then have as many, or the means would not be
  alike (an error names the view sets that differ)."""
  lengths = sorted({r["steps"] for r in rows})
  if steps is None:
    if len(lengths) != 1:
      raise ValueError(f"the rows hold final models of {lengths} steps: choose one")
    steps = lengths[0]
  if steps not in lengths:
    raise ValueError(f"no final models of {steps} steps; the rows hold {lengths}")
  chosen = [r for r in rows if r["steps"] == steps
            and (mean_over_inits or r["train_seed"] == r["seed"])]
  models = {}
  for r in chosen:
    models.setdefault((r["strategy"], r["seed"], r["views"]), []).append(r)
  counts = {key: len(group) for key, group in models.items()}
  if len(set(counts.values())) > 1:
    most = max(counts.values())
    short = sorted(f"{s} seed {seed} ({n} views): {c}" for (s, seed, n), c in counts.items()
                   if c < most)
    raise ValueError(f"view sets with fewer than {most} initialisations: {', '.join(short)}")
  records = {}
  for (strategy, seed, n), group in models.items():
    rec = records.setdefault((strategy, seed), {
        "strategy": strategy, "label": group[0]["label"], "seed": seed, "inits": len(group),
        "metrics": {}})
    rec["metrics"][str(n)] = {m: float(np.mean([r[m] for r in group])) for m in ("psnr", "ssim")}
  return list(records.values())
