"""The benchmark scripts' measurement functions, in this process, at tiny sizes.

Timings at these sizes mean nothing; what is checked is that every script measures what it
says (every variant present, ratios taken within one run, curves over the right models)
and refuses missing inputs with a message naming the flag.
"""

import json
import math
import os

import numpy as np
import pytest
from bench_testlib import import_script

from configs import train as train_configs
from mfsample import _bench

SCRIPTS = {name: import_script(name) for name in (
    "train_step", "candidate_scoring", "train_quality", "tradeoffs", "capture", "scaling")}
train_step = SCRIPTS["train_step"][0]
candidate_scoring = SCRIPTS["candidate_scoring"][0]
train_quality = SCRIPTS["train_quality"][0]
tradeoffs = SCRIPTS["tradeoffs"][0]
capture = SCRIPTS["capture"][0]
scaling = SCRIPTS["scaling"][0]


def tiny_base():
  """The tiny synthetic training config at SH degree 1, 6 steps, no densification reached.

  Shared by the train_step, train_quality and tradeoffs tests: equal step configs share
  one compilation of the training step.
  """
  config = train_configs.get_config("tiny")
  config.model.sh_degree = 1
  config.train.num_steps = 6
  config.eval.save_images = 1
  config.eval.export_ply = False
  return config


# ------------------------------------------------------------------ command lines, machine


def test_outputs_default_to_the_ignored_workdirs_folder():
  paths = {f"{script}.{flag}": default for script, (_, defaults) in SCRIPTS.items()
           for flag, default in defaults.items()
           if flag in ("out", "plot", "workdir", "train_step", "stochastic", "deterministic")}
  assert len(paths) == 11
  assert all(p.startswith("workdirs/benchmarks/") for p in paths.values()), paths
  data = {s: d["data"] for s, (_, d) in SCRIPTS.items() if "data" in d}
  assert data == dict.fromkeys(("train_step", "train_quality", "tradeoffs"),
                               "data/nerf_synthetic/lego")


def test_machine_record_names_the_hardware_and_jax_version():
  import jax

  record = _bench.machine()
  assert record["jax"] == jax.__version__
  assert record["cpu_count"] >= 1 and record["device_count"] >= 1
  assert record["device_kind"] and record["platform"] and record["backend"]


def test_missing_lego_names_the_flag_and_where_to_get_it(tmp_path):
  with pytest.raises(FileNotFoundError, match="--data") as info:
    _bench.require_scene_folder(str(tmp_path / "lego"), "--data")
  assert "nerf_synthetic.zip" in str(info.value) and str(tmp_path) in str(info.value)


# ------------------------------------------------------------------ train_step.py


def test_train_step_falls_back_to_a_synthetic_scene_of_the_same_size(tmp_path):
  config, scene = train_step.base_config(str(tmp_path), 48, 500, 2)
  assert scene == "synthetic" and config.data.kind == "synthetic"
  assert (config.data.width, config.data.height) == (48, 48)
  assert config.model.init_points == 500 and config.sampler.num_samples == 2
  with pytest.raises(ValueError, match="rank"):
    train_step.variant_config(config, "rankx")
  c = train_step.variant_config(config, "rank4@8")
  assert (c.sampler.kind, c.sampler.rank, c.render.chunks_per_step) == ("lowrank", 4, 8)
  assert config.sampler.kind == "lowrank" and config.render.chunks_per_step == 16  # a copy


@pytest.mark.slow
def test_train_step_rounds_interleave_and_ratios_are_within_rounds():
  base = tiny_base()
  variants = ["deterministic", "rank2"]
  order = []

  def measure(variant):
    order.append(variant)
    return train_step.measure_variant(train_step.variant_config(base, variant), steps=2,
                                      warmup=1)

  rounds = train_step.run_rounds(variants, 2, measure, log=lambda _: None)
  assert order == variants * 2  # interleaved: every round visits every variant
  table = train_step.summarize(variants, rounds)
  assert list(table) == variants
  det, rank2 = table["deterministic"], table["rank2"]
  assert det["ratio"] == 1.0 and det["vs_first"] == 1.0
  expected = np.median([r["rank2"]["ms_median"] / r["deterministic"]["ms_median"]
                        for r in rounds])
  assert rank2["ratio"] == pytest.approx(expected) and rank2["ratio"] > 0
  for variant in variants:
    assert len(table[variant]["ms_rounds"]) == 2
    assert all(len(r[variant]["ms_all"]) == 2 and r[variant]["ms_min"] > 0 for r in rounds)
    assert table[variant]["peak_rss_mb"] > 0
  # B_hat of rank k adds k floats per mean float: rank 2 trains 3x the deterministic's.
  assert rank2["params_per_gaussian"] == 3 * det["params_per_gaussian"]
  assert rounds[0]["rank2"]["live"] == base.model.init_points
  assert rounds[0]["rank2"]["resolution"] == base.data.height


@pytest.mark.slow
def test_train_step_reports_the_renderer_share_from_a_fitted_start_budget():
  config = train_step.variant_config(tiny_base(), "rank2")
  config.render.max_intersections = 256  # too small: the start budget is fitted first
  result = train_step.measure_variant(config, steps=2, warmup=1, render_share=True,
                                      fit_start_budget=True)
  assert result["budget"] > 256 and result["compositor"] == "jnp" and result["samples"] == 1
  assert result["render_forward_backward_ms"] > 0 and result["render_intersections"] > 0
  assert result["outside_renderer_share"] == pytest.approx(
      1.0 - result["render_forward_backward_ms"] / result["ms_median"])


# ------------------------------------------------------------------ candidate_scoring.py


@pytest.mark.slow
def test_candidate_scoring_times_every_scorer_and_their_ratios():
  result = candidate_scoring.run(num_gaussians=64, resolution=16, num_candidates=2,
                                 samples=2, probes=["1"], repeats=2)
  ours = result["ours_seconds_per_candidate"]
  assert ours > 0 and result["probes"] == [1]
  for k in (1,):
    fisher = result[f"fisher_{k}_probes_seconds_per_candidate"]
    assert fisher > 0
    assert result[f"ratio_fisher_{k}_probes_over_ours"] == pytest.approx(fisher / ours)
  budget = result["budget"]
  assert budget >= 512 and budget & (budget - 1) == 0  # grown in powers of two


# ------------------------------------------------------------------ train_quality.py + tradeoffs.py


@pytest.fixture(scope="module")
def quality_runs(tmp_path_factory):
  """(workdir, rows) of the three train_quality variants trained on the tiny scene."""
  workdir = str(tmp_path_factory.mktemp("quality"))
  rows = train_quality.run(tiny_base(), list(train_quality.VARIANTS), workdir)
  return workdir, rows


@pytest.mark.slow
def test_train_quality_trains_every_variant_and_resumes_without_retraining(quality_runs):
  workdir, rows = quality_runs
  assert list(rows) == ["deterministic", "rank2", "rank2_every_step"]
  for name, row in rows.items():
    assert row["steps"] == 6 and math.isfinite(row["psnr"]) and 0 < row["ssim"] <= 1
    assert row["num_views"] == 4 and row["num_train_views"] == 12
    with open(os.path.join(workdir, name, "config.json")) as f:
      config = json.load(f)
    for field, value in train_quality.VARIANTS[name].items():
      group, leaf = field.split(".")
      assert config[group][leaf] == value
  assert [rows[n]["sampler"] for n in rows] == ["deterministic", "lowrank", "lowrank"]

  metrics = os.path.join(workdir, "rank2", "metrics.json")
  mtime = os.path.getmtime(metrics)
  again = train_quality.run(tiny_base(), ["rank2"], workdir)
  assert again["rank2"] == rows["rank2"] and os.path.getmtime(metrics) == mtime  # only read

  longer = tiny_base()
  longer.train.num_steps = 7
  with pytest.raises(ValueError, match="train.num_steps"):
    train_quality.run(longer, ["rank2"], workdir)


def test_train_quality_overrides_and_unknown_variants():
  assert train_quality.parse_overrides(["model.max_gaussians=4000", "--config.seed=3",
                                        "data.path=x/y"]) == {
      "model.max_gaussians": 4000, "seed": 3, "data.path": "x/y"}
  with pytest.raises(ValueError, match="field=value"):
    train_quality.parse_overrides(["seed"])
  with pytest.raises(ValueError, match="rank3"):
    train_quality.variant_config(tiny_base(), "rank3")
  with pytest.raises(KeyError, match="model.nope"):
    train_quality.variant_config(tiny_base(), "rank2", {"model.nope": 1})


def test_tradeoffs_refuses_missing_inputs_naming_the_flag(tmp_path):
  with pytest.raises(FileNotFoundError, match="--stochastic"):
    tradeoffs.check_run(str(tmp_path), "--stochastic")
  missing = str(tmp_path / "train_step.json")
  with pytest.raises(FileNotFoundError, match="--train_step") as info:
    tradeoffs.read_train_step(missing)
  assert missing in str(info.value)


@pytest.mark.slow
def test_tradeoffs_curves_on_trained_runs(quality_runs, tmp_path):
  workdir, _ = quality_runs
  stochastic = os.path.join(workdir, "rank2_every_step")
  tradeoffs.check_run(stochastic, "--stochastic")
  dataset, model, settings = tradeoffs.load_run(stochastic)
  unc = tradeoffs.samples_and_resolution(model, dataset, settings, candidates=4,
                                         samples=["2", "4"], reference_samples=4, scrambles=2,
                                         downscales=["1"], repeats=1)
  assert [r["M"] for r in unc["samples"]] == [2, 4]
  for row in unc["samples"]:
    assert row["ms_per_candidate"] > 0 and row["median_relative_error"] >= 0
    assert -1 <= row["spearman_vs_reference"] <= 1
  (full,) = unc["downscales"]  # (each further downscale is one more compilation)
  assert full["resolution"] == unc["resolution"] == 32
  assert full["spearman_vs_full"] == pytest.approx(1.0)  # the same U, ranked against itself

  dataset, model, settings = tradeoffs.load_run(os.path.join(workdir, "deterministic"))
  # (A smaller kept fraction would cost two more compilations of the same code path.)
  rend = tradeoffs.sh_and_budget(model, dataset, settings, test_views=2, keep=["1.0"],
                                 repeats=1)
  assert [r["degree"] for r in rend["sh_degree"]] == [1, 0]
  (everything,) = rend["keep"]
  assert everything["gaussians"] == rend["live_gaussians"] == model.num_live
  # Every band and every Gaussian kept is the same model, rendered the same way.
  assert everything["psnr"] == pytest.approx(rend["sh_degree"][0]["psnr"], abs=1e-4)
  assert all(r["forward_ms"] > 0 for r in rend["sh_degree"] + rend["keep"])

  step_json = tmp_path / "train_step.json"
  step_json.write_text(json.dumps({"machine": {"jax": "x"}, "table": {"rank2": {}}}))
  rank = tradeoffs.read_train_step(str(step_json))
  plot = str(tmp_path / "figs" / "tradeoffs.png")
  tradeoffs.plot({"uncertainty": unc, "rendering": rend, "rank": rank}, plot)
  assert os.path.getsize(plot) > 0


# ------------------------------------------------------------------ capture.py


@pytest.mark.slow
def test_capture_times_every_spp_and_reads_the_pool_back_from_its_cache(tmp_path):
  from mfsample import scenes

  if not scenes.mitsuba_available():
    pytest.skip("needs Mitsuba 3 (the scenes extra)")
  scene = scenes.get_scene()
  report = capture.spp_sweep(scene, size=8, views=1, spps=(1, 4), variants=["scalar_rgb"],
                             sh_degree=1, sh_spp=1, log=lambda _: None)
  assert [(r["variant"], r["spp"]) for r in report["rgbad"]] == [("scalar_rgb", 1),
                                                                 ("scalar_rgb", 4)]
  assert all(r["seconds_per_capture"] > 0 for r in report["rgbad"])
  (basis,) = report["sh_basis"]
  assert basis["images"] == 4 and basis["seconds_per_capture"] > 0
  pool = capture.pool_capture(scene, size=8, candidates=2, test=1, cache_dir=str(tmp_path))
  assert pool["views"] == 3 and pool["seconds"] > 0
  cached = [f for _, _, files in os.walk(tmp_path) for f in files if f.endswith(".npz")]
  assert len(cached) == 3  # every view was stored by the first pass ...
  assert pool["cached_seconds"] < pool["seconds"]  # ... and read, not rendered, by the second


# ------------------------------------------------------------------ scaling.py


def test_scaling_ratios_are_taken_within_rounds():
  # Two rounds; in the second the whole machine is twice as slow: the ratios hold.
  times = {1: [(1.0, 1.0), (2.0, 2.0)], 2: [(0.6, 1.1), (1.2, 2.2)]}
  table = scaling.summarize(times, items=8)
  assert table[1]["speedup"] == 1.0 and table[1]["cpu_ratio"] == 1.0
  assert table[2]["speedup"] == pytest.approx(1 / 0.6)
  assert table[2]["cpu_ratio"] == pytest.approx(1.1)
  assert table[2]["per_second"] == pytest.approx(8 / 0.9)  # items / median wall-clock
  assert table[2]["wall_rounds"] == [0.6, 1.2]


@pytest.mark.slow
def test_scaling_measures_scoring_and_a_training_step_per_device_count():
  views, setup, state = scaling.setup_run(batch_size=2, resolution=16, points=64)
  assert setup.step_config.batch_size == 2 and state.model.num_live == 64
  assert len(views) == 12 and views.images.shape[1:3] == (16, 16)
  score, budget = scaling.scoring([1], state.model, resolution=16, num_candidates=2,
                                  samples=2, rounds=2)
  assert budget >= 512 and score[1]["speedup"] == 1.0 and len(score[1]["wall_rounds"]) == 2
  assert score[1]["per_second"] > 0 and score[1]["cpu_seconds"] > 0
  train, _ = scaling.training([1], views, setup, state, rounds=2)
  assert train[1]["per_second"] > 0 and len(train[1]["cpu_rounds"]) == 2


@pytest.mark.slow
def test_suite_tiers_names_the_modules_a_selection_leaves_untouched():
  """`benchmarks/suite_tiers.py` on one small test file: the module it tests is touched,
  modules it never calls are listed as untouched."""
  suite_tiers, defaults = import_script("suite_tiers")
  assert defaults["out"].startswith("workdirs/benchmarks/")
  root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
  record = suite_tiers.run("not slow", 1, ["tests/core/test_streams.py"], root=root)
  assert "passed" in record["tests"] and record["seconds"] > 0
  assert 0 < record["line_coverage_percent"] < 100
  assert "mfsample/streams.py" not in record["untouched_modules"]
  assert "mfsample/data/colmap.py" in record["untouched_modules"]
  assert len(record["untouched_modules"]) < record["modules"]
