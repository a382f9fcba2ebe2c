"""`run_uncertainty_quality`: both parts of the experiment, resumable, with tables and figures.

Writes to the workdir: `config.json`; the AUSE part's `ause/<scene>-seed<s>-<model>.json`
(+ `.npz` maps) and `uncertainty_quality_<scene>.png`; the candidates part's
`candidates/<case>.json`; and `table.md` and `results.json` over everything. Finished units
are loaded, not recomputed, by a later call with the same config; a workdir whose units
were made with another protocol is refused before anything is written, naming the fields.
"""

import time

from mfsample import jobs
from mfsample.config_blocks import speed_only_fields
from mfsample.quality import benchmark, candidates, figures, tables
from mfsample.quality.config import validate


def run_uncertainty_quality(config, workdir):
  """Runs (or resumes) the enabled parts of the experiment; writes and returns the results.

  Returns:
    the results dict (as in `results.json`): "ause" ({"summary", "records"}) and/or
    "candidates" (`candidates.run_candidates`'s dict), and "seconds_this_call".
  """
  t0 = time.perf_counter()
  with jobs.open_workdir(JOB, config, workdir) as wd:
    # The candidates' pool is loaded and checked before any model of either part trains.
    pool = candidates.candidates_pool(config) if config.candidates.enabled else None
    wd.write_config()
    results, markdown = {}, []
    if config.ause.enabled:
      a = config.ause
      bar = wd.progress(len(a.scenes) * len(a.seeds) * len(benchmark.model_names(config)),
                        "uncertainty quality (AUSE)")
      out = benchmark.run_ause(config, wd, bar)
      bar.close()
      scenes = list(a.scenes)
      summary = tables.ause_summary(out["records"], scenes)
      markdown.append(tables.ause_markdown(
          summary, scenes, f"## AUSE: {len(a.seeds)} seed(s), "
          f"{len(out['views'][scenes[0]][1])} test views per scene, mean over both"))
      figure_paths = {}
      if config.figures.enabled and wd.writes:
        wd.stage("figures of the AUSE benchmark")
        for scene in scenes:
          figure_paths[scene] = figures.scene_figure(
              scene, out["views"][scene][1], out["records"], out["arrays"],
              wd.file(f"uncertainty_quality_{scene}.png"), view=int(config.figures.test_view))
      results["ause"] = {"scenes": scenes, "seeds": list(a.seeds), "summary": summary,
                         "records": out["records"], "figures": figure_paths}
    if config.candidates.enabled:
      c = config.candidates
      bar = wd.progress(len(c.steps) * len(c.samplers) * len(c.seeds) * len(c.views),
                        "uncertainty quality (candidates)")
      results["candidates"] = candidates.run_candidates(config, wd, bar, pool)
      bar.close()
      markdown.append(tables.candidates_markdown(
          results["candidates"], f"## U against the round model's error at the candidates "
          f"(`{results['candidates']['scene']}`)"))
    wd.write_text("table.md", "\n".join(markdown))
    results["seconds_this_call"] = time.perf_counter() - t0
    wd.write_json("results.json", results)
    return results


# Fields a later call on the same workdir may change: which units to run (records hold
# what they need to be reused), how they are shown, and speed-only training fields.
FREE_FIELDS = (
    "progress", "figures", "data.progress", "ause.enabled", "ause.scenes", "ause.seeds",
    "ause.samplers", "ause.baselines", "candidates.enabled", "candidates.steps",
    "candidates.samplers", "candidates.samples", "candidates.seeds", "candidates.views",
    "candidates.planning.progress", "candidates.planning.data.progress",
) + speed_only_fields("train") + speed_only_fields("candidates.planning.round_train")
JOB = jobs.Job("uncertainty quality", "uncertainty_quality", run_uncertainty_quality,
               validate, FREE_FIELDS, ("ause", "candidates"), report=jobs.table_report)
