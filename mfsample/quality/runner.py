"""`run_uncertainty_quality`: both parts of the experiment, resumable, with tables and figures.

Writes to the workdir: `config.json`; the AUSE part's `ause/<scene>-seed<s>-<model>.json`
(+ `.npz` maps) and `uncertainty_quality_<scene>.png`; the candidates part's
`candidates/<case>.json`; and `table.md` and `results.json` over everything. Finished units
are loaded, not recomputed, by a later call with the same config; a workdir whose units
were made with another protocol is refused before anything is written, naming the fields.
"""

import math
import os
import time

from mfsample import config_checks as checks
from mfsample import workdir as workdir_lib
from mfsample._json import write_json, write_text
from mfsample.quality import benchmark, candidates, figures, tables
from mfsample.train.loop import SPEED_ONLY_FIELDS

# Fields a later call on the same workdir may change: which units to run (records hold
# what they need to be reused), how they are shown, and speed-only training fields.
RESUME_FREE_FIELDS = (
    "progress", "figures", "data.progress", "ause.enabled", "ause.scenes", "ause.seeds",
    "ause.samplers", "ause.baselines", "candidates.enabled", "candidates.steps",
    "candidates.samplers", "candidates.samples", "candidates.seeds", "candidates.views",
    "candidates.planning.progress", "candidates.planning.data.progress",
) + tuple(f"train.{f}" for f in SPEED_ONLY_FIELDS) + tuple(
    f"candidates.planning.round_train.{f}" for f in SPEED_ONLY_FIELDS)


def check_config(config):
  """Validates the fields the experiment reads; raises `ConfigError` naming the field."""
  a, d = config.ause, config.data
  if not (a.enabled or config.candidates.enabled):
    raise checks.ConfigError("config.ause.enabled and config.candidates.enabled are both "
                             "False: nothing to run")
  if a.enabled:
    checks.check_choice(config, "data.kind", ("scene", "synthetic"))
    if d.kind == "scene":
      from mfsample.scenes import SCENES
      checks.check_sequence(config, "ause.scenes", item_choices=SCENES, distinct=True)
    else:
      checks.check_sequence(config, "ause.scenes", distinct=True)
    checks.check_sequence(config, "ause.seeds", item_minimum=0, distinct=True)
    _check_samplers(config, "ause.samplers", min_length=0)
    checks.check_sequence(config, "ause.baselines", item_choices=benchmark.BASELINES,
                          min_length=0, distinct=True)
    if not (a.samplers or a.baselines):
      raise checks.ConfigError("config.ause.samplers and config.ause.baselines are both "
                               "empty: no method to measure")
    _check_samplers(config, "ause.posthoc_sampler", min_length=1, single=True)
    checks.check_int(config, "ause.posthoc_steps", minimum=1)
    checks.check_int(config, "ause.samples", minimum=2)
    checks.check_int(config, "ause.z_seed", minimum=0)
    checks.check_int(config, "data.width", minimum=1)
    checks.check_int(config, "data.height", minimum=1)
    spp = checks.check_int(config, "data.spp", minimum=1)
    if math.isqrt(spp) ** 2 != spp:
      raise checks.ConfigError(f"config.data.spp = {spp}: must be a perfect square (the "
                               "stratified sampler's grid)")
    views = checks.check_int(config, "data.arc.num_views", minimum=3)
    if views % 2 == 0:
      raise checks.ConfigError(f"config.data.arc.num_views = {views}: must be odd (the "
                               "first and the last view train)")
    checks.check_float(config, "data.arc.span_deg", above=0.0, maximum=360.0)
    checks.check_float(config, "data.arc.polar_deg", above=0.0, below=180.0)
    checks.check_float(config, "data.arc.distance", above=0.0)
    checks.check_float(config, "data.arc.fov_deg", above=0.0, below=180.0)
    checks.check_float(config, "mask.true_alpha_min", above=0.0, maximum=1.0)
    checks.check_float(config, "mask.model_alpha_min", minimum=0.0, below=1.0)
    steps = checks.check_int(config, "train.train.num_steps", minimum=1)
    if int(config.train.densify.start) < steps:
      raise checks.ConfigError(
          f"config.train.densify.start = {config.train.densify.start}: the models train "
          f"with fixed shapes; it must be >= config.train.train.num_steps ({steps})")
    checks.check_int(config, "fisher.train_probes", minimum=1)
    checks.check_int(config, "fisher.pixel_probes", minimum=1)
    checks.check_float(config, "fisher.reg", above=0.0)
    checks.check_int(config, "activenerf.steps", minimum=1)
    checks.check_float(config, "activenerf.lr", above=0.0)
    checks.check_float(config, "activenerf.prior_var", above=0.0)
    checks.check_float(config, "activenerf.beta_min", above=0.0)
    checks.check_float(config, "activenerf.prior_weight", minimum=0.0)
    checks.check_int(config, "figures.test_view", minimum=0, maximum=views // 2 - 1)
  if config.candidates.enabled:
    checks.check_sequence(config, "candidates.steps", item_minimum=1, distinct=True)
    _check_samplers(config, "candidates.samplers", min_length=1)
    checks.check_sequence(config, "candidates.samples", item_minimum=2, distinct=True)
    checks.check_sequence(config, "candidates.seeds", item_minimum=0, distinct=True)
    counts = checks.check_sequence(config, "candidates.views", item_minimum=1, distinct=True)
    planning = config.candidates.planning
    if planning.data.kind != "blender" and max(counts) >= int(planning.data.num_candidates):
      raise checks.ConfigError(
          f"config.candidates.views = {tuple(counts)}: every count must leave unused "
          f"candidates (< candidates.planning.data.num_candidates = "
          f"{planning.data.num_candidates})")


def _check_samplers(config, field, min_length, single=False):
  """Sampler flags ("kind" or "kind:k"); `single`: one flag (a string field), not a sequence."""
  if single:
    flags = (checks.get_field(config, field),)
  else:
    flags = checks.check_sequence(config, field, min_length=min_length, distinct=True)
  for flag in flags:
    try:
      benchmark.parse_sampler(flag)
    except ValueError as e:
      raise checks.ConfigError(f"config.{field}: {e}") from None


def check_resumable(config, workdir):
  """Refuses to add to a workdir whose finished units were made with another protocol.

  Raises:
    mfsample.workdir.WorkdirError: naming the differing fields.
  """
  workdir_lib.check_same_config(
      config, workdir, free_fields=RESUME_FREE_FIELDS,
      has_results=workdir_lib.holds_results(workdir, "ause", "candidates"),
      remedy=f"use a new --workdir, or remove {workdir}/ause and {workdir}/candidates to "
             "redo them")


def run_uncertainty_quality(config, workdir):
  """Runs (or resumes) the enabled parts of the experiment; writes and returns the results.

  Returns:
    the results dict (as in `results.json`): "ause" ({"summary", "records"}) and/or
    "candidates" (`candidates.run_candidates`'s dict), and "seconds_this_call".
  """
  from tqdm.auto import tqdm

  t0 = time.perf_counter()
  check_config(config)
  check_resumable(config, workdir)
  os.makedirs(workdir, exist_ok=True)
  workdir_lib.write_config(config, workdir)
  results, markdown = {}, []
  if config.ause.enabled:
    a = config.ause
    bar = tqdm(total=len(a.scenes) * len(a.seeds) * len(benchmark.model_names(config)),
               desc="uncertainty quality (AUSE)", disable=not config.progress,
               dynamic_ncols=True)
    out = benchmark.run_ause(config, workdir, bar)
    bar.close()
    scenes = list(a.scenes)
    summary = tables.ause_summary(out["records"], scenes)
    markdown.append(tables.ause_markdown(
        summary, scenes, f"## AUSE: {len(a.seeds)} seed(s), {len(out['views'][scenes[0]][1])} "
        f"test views per scene, mean over both"))
    figure_paths = {}
    if config.figures.enabled:
      for scene in scenes:
        figure_paths[scene] = figures.scene_figure(
            scene, out["views"][scene][1], out["records"], workdir,
            os.path.join(workdir, f"uncertainty_quality_{scene}.png"),
            view=int(config.figures.test_view))
    results["ause"] = {"scenes": scenes, "seeds": list(a.seeds), "summary": summary,
                       "records": out["records"], "figures": figure_paths}
  if config.candidates.enabled:
    c = config.candidates
    bar = tqdm(total=len(c.steps) * len(c.samplers) * len(c.seeds) * len(c.views),
               desc="uncertainty quality (candidates)", disable=not config.progress,
               dynamic_ncols=True)
    results["candidates"] = candidates.run_candidates(config, workdir, bar)
    bar.close()
    markdown.append(tables.candidates_markdown(
        results["candidates"], f"## U against the round model's error at the candidates "
        f"(`{results['candidates']['scene']}`)"))
  write_text(os.path.join(workdir, "table.md"), "\n".join(markdown))
  results["seconds_this_call"] = time.perf_counter() - t0
  write_json(os.path.join(workdir, "results.json"), results, indent=1)
  return results
