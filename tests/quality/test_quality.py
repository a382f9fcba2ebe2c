"""Tests of mfsample.quality: the arc, the maps and the experiment at a tiny size, in-process."""

import json
import math
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from planning_testlib import poses, random_model

from configs import uncertainty_quality
from mfsample import config_checks
from mfsample import view_uncertainty as unc
from mfsample.planning import training
from mfsample.quality import arc, benchmark, maps, run_uncertainty_quality, tables
from mfsample.quality.config import validate as validate_quality
from mfsample.renderer import RenderSettings, render
from mfsample.samplers import sample_z


def test_arc_cameras_face_the_target_and_split_odd_from_even():
  cfg = uncertainty_quality.get_config().data.arc
  cams = arc.arc_cameras(cfg, 32, 24)
  target = np.asarray(cfg.target)
  assert cams.batch_shape == (9,)
  # Every camera looks at the target (it projects to the image centre), at `distance`.
  pix, depth = cams.project(jnp.broadcast_to(jnp.asarray(target, jnp.float32), (9, 1, 3)))
  np.testing.assert_allclose(np.asarray(pix)[:, 0], np.tile([16.0, 12.0], (9, 1)), atol=1e-3)
  np.testing.assert_allclose(np.asarray(depth), cfg.distance, rtol=1e-5)
  offset = np.asarray(cams.center) - target
  azimuth = np.degrees(np.arctan2(offset[:, 1], offset[:, 0]))
  np.testing.assert_allclose(azimuth, cfg.azimuth_deg + cfg.span_deg * (np.arange(9) / 8 - 0.5),
                             atol=1e-3)
  polar = np.degrees(np.arccos(offset[:, 2] / np.linalg.norm(offset, axis=1)))
  np.testing.assert_allclose(polar, cfg.polar_deg, atol=1e-3)
  train, test = arc.split(9)
  np.testing.assert_array_equal(train, [0, 2, 4, 6, 8])
  np.testing.assert_array_equal(test, [1, 3, 5, 7])


def test_depth_error_counts_covered_pixels_only():
  err, mask = maps.depth_error(np.array([[1.0, 2.0], [3.0, 0.0]]),
                               np.array([[0.9, 0.4], [1.0, 0.0]]),
                               np.array([[1.5, 2.0], [2.0, 0.0]]),
                               np.array([[1.0, 1.0], [0.5, 0.0]]),
                               true_alpha_min=0.999, model_alpha_min=0.5)
  np.testing.assert_allclose(err, [[0.5, 0.0], [1.0, 0.0]])
  np.testing.assert_array_equal(mask, [[True, False], [False, False]])


@pytest.mark.slow
def test_sample_maps_match_the_uncertainty_module():
  # Ours' colour map is Eq. 10's per-pixel term (`uncertainty.uncertainty`); the depth map is
  # the variance of the samples' expected depths. (Model, camera and settings as in
  # tests/core/test_uncertainty.py, whose compilations these calls share.)
  model = random_model("lowrank")
  camera = poses.spherical_camera(np.array([0.15, 0.3], np.float32),
                                  poses.SphereSpec(radius=3.0, v_range=(0.05, 0.95), width=20,
                                                   height=16))
  z = sample_z(model, 2)
  s = RenderSettings(max_intersections=1 << 12)
  out = maps.sample_maps(model, camera, z, jnp.zeros(3), settings=s)
  ref = unc.uncertainty(model, camera, z, settings=s)
  assert not bool(jnp.any(out.stats.overflow)) and float(jnp.max(out.colour)) > 0
  np.testing.assert_allclose(out.colour, ref.pixel_map, rtol=1e-5, atol=1e-9)
  g = unc.sample_gaussians(model, z)
  depths = [render(jax.tree.map(lambda x, i=i: x[i], g), camera, settings=s).expected_depth()
            for i in (0, 1)]
  np.testing.assert_allclose(out.depth, np.var(np.stack(depths), axis=0), rtol=1e-4,
                             atol=1e-7)


def test_sampler_flags_and_labels():
  assert benchmark.parse_sampler("lowrank:10") == ("lowrank", 10)
  assert benchmark.parse_sampler("diagonal") == ("diagonal", None)
  for bad in ("lowrank:0", "lowrank:x", "full"):
    with pytest.raises(ValueError, match="sampler"):
      benchmark.parse_sampler(bad)
  plan = benchmark.model_recipe(uncertainty_quality.get_config().train, "block:4")
  assert (plan.spec.kind, plan.spec.rank) == ("block", 4)
  assert benchmark.model_recipe(uncertainty_quality.get_config().train,
                                "deterministic").spec.kind == "deterministic"
  assert tables.method_label("lowrank:2", "colour") == "Ours, rank 2: U (Eq. 10)"
  assert tables.method_label("deterministic", "fisher") == "FisherRF"


@pytest.mark.parametrize("field, value, message", [
    ("ause.scenes", ("tabletop", "nope"), "config.ause.scenes: 'nope' is not one of"),
    ("ause.samplers", ("lowrank:2", "full"), "config.ause.samplers: sampler 'full'"),
    ("data.arc.num_views", 8, "config.data.arc.num_views = 8: must be odd"),
    ("ause.samples", 1, "config.ause.samples = 1: must be an integer >= 2"),
    ("data.spp", 10, "config.data.spp = 10: must be a perfect square"),
    ("train.densify.start", 10, "config.train.densify.start = 10"),
    ("figures.test_view", 4, r"config.figures.test_view = 4: must be an integer in \[0, 3\]"),
    ("ause.baselines", ("posthoc", "nope"), "config.ause.baselines: 'nope' is not one of"),
    ("ause.posthoc_sampler", "deterministic", "config.ause.posthoc_sampler: sampler"),
    ("ause.posthoc_steps", 0, "config.ause.posthoc_steps = 0: must be an integer >= 1"),
    ("candidates.planning.strategy.score_downscale", 65,
     "config.candidates.planning.strategy.score_downscale = 65: the pool's images are 64 x 64"),
])
def test_bad_configs_are_refused_naming_the_field(field, value, message):
  config = uncertainty_quality.get_config()
  node = config
  *parents, leaf = field.split(".")
  for p in parents:
    node = node[p]
  node[leaf] = value
  if field.startswith("candidates."):
    config.candidates.enabled = True
  with pytest.raises(config_checks.ConfigError, match=message):
    validate_quality(config)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
  workdir = tmp_path_factory.mktemp("quality")
  config = uncertainty_quality.get_config("tiny")
  return config, workdir, run_uncertainty_quality(config, str(workdir))


@pytest.mark.slow
def test_tiny_experiment_writes_both_parts(tiny_run):
  config, workdir, results = tiny_run
  ause = results["ause"]
  methods = ["deterministic/fisher", "deterministic/activenerf", "lowrank:2/colour",
             "lowrank:2/depth"]
  assert ause["summary"]["methods"] == methods
  for measure in ("mae", "rmse"):
    for key in methods + ["lowrank:2/constant"]:
      value = ause["summary"]["ause"][measure][key]["synthetic"]
      assert 0.0 <= value <= 1.0, (measure, key, value)
  assert len(ause["records"]) == 2 and all(len(r["views"]) == 2 for r in ause["records"])
  with np.load(workdir / "ause" / "synthetic-seed0-lowrank2.npz") as f:
    assert f["map_colour"].shape == (2, 24, 24) and f["mask"].dtype == bool
    assert np.all(f["map_colour"] >= 0) and np.any(f["mask"])
  assert (workdir / "uncertainty_quality_synthetic.png").stat().st_size > 0
  cand = results["candidates"]
  assert [(r["samples"], len(r["per_case_rho_u_error"])) for r in cand["rows"]] == [(8, 2),
                                                                                      (2, 2)]
  assert all(-1.0 <= r["rho_u_error"] <= 1.0 for r in cand["rows"])
  (paired,) = cand["paired"]
  assert paired["minus"] == {"samples": 8} and paired["cases"] == 2
  table = (workdir / "table.md").read_text()
  assert "| Ours, rank 2: U (Eq. 10) |" in table and "| FisherRF |" in table
  assert "rho(U, error)" in table
  assert json.loads((workdir / "results.json").read_text())["ause"]["scenes"] == ["synthetic"]


@pytest.mark.slow
def test_tiny_experiment_resumes_and_refuses_another_protocol(tiny_run, monkeypatch):
  config, workdir, results = tiny_run

  def no_training(*args, **kwargs):
    raise AssertionError("a finished unit was trained again")

  monkeypatch.setattr(training, "train_on_views", no_training)
  monkeypatch.setattr("mfsample.planning.runner.Trainer.round_model", no_training)
  again = run_uncertainty_quality(config, str(workdir))
  assert again["ause"]["summary"] == results["ause"]["summary"]
  assert again["candidates"]["rows"] == results["candidates"]["rows"]
  changed = uncertainty_quality.get_config("tiny")
  changed.mask.model_alpha_min = 0.3
  changed.figures.enabled = False  # free to change
  with pytest.raises(ValueError, match="different config.*mask.model_alpha_min"):
    run_uncertainty_quality(changed, str(workdir))
  assert math.isfinite(again["seconds_this_call"])


@pytest.mark.slow
def test_posthoc_baseline_keeps_the_mean_and_scores_its_maps(tmp_path, monkeypatch):
  # The deterministic model of the tiny run (the same training compilation), B_hat fitted to
  # it post hoc; the fitted field is caught on its way to the maps.
  config = uncertainty_quality.get_config("tiny")
  config.candidates.enabled = False
  config.figures.enabled = False
  config.ause.samplers = ()
  config.ause.baselines = ("posthoc",)
  config.ause.posthoc_steps = 20
  fits = []

  def spy(config, model, *args, **kwargs):
    fit = fit_posthoc(config, model, *args, **kwargs)
    fits.append((model, fit.state.model))
    return fit

  fit_posthoc = benchmark.fit_posthoc
  monkeypatch.setattr(benchmark, "fit_posthoc", spy)
  results = run_uncertainty_quality(config, str(tmp_path))
  (model, field), = fits
  live = np.asarray(model.mask)
  n = int(live.sum())
  assert int(field.num_live) == n
  for g, v in model.params.mean.items():  # the deterministic model's mean, bit for bit
    np.testing.assert_array_equal(np.asarray(field.params.mean[g])[:n], np.asarray(v)[live],
                                  err_msg=g)
  assert any(float(np.max(v)) > 0 for v in jax.tree.leaves(field.params.b_hat))
  (record,) = results["ause"]["records"]
  assert record["methods"] == ["posthoc_colour", "posthoc_depth"]
  assert record["posthoc"]["steps"] == 20 and record["posthoc"]["mean_unchanged"]
  with np.load(tmp_path / "ause" / "synthetic-seed0-deterministic.npz") as f:
    for k in ("map_posthoc_colour", "map_posthoc_depth"):
      assert f[k].shape == (2, 24, 24) and np.all(np.isfinite(f[k])) and np.all(f[k] >= 0)
    assert np.max(f["map_posthoc_colour"]) > 0
  for measure in ("mae", "rmse"):
    for key in ("deterministic/posthoc_colour", "deterministic/posthoc_depth",
                "deterministic/constant"):
      value = results["ause"]["summary"]["ause"][measure][key]["synthetic"]
      assert 0.0 <= value <= 1.0, (measure, key, value)
  assert "| Post-hoc B_hat: U (Eq. 10) |" in (tmp_path / "table.md").read_text()


# ------------------------------------------------------------------ pieces (the fast tier)


def test_a_config_with_no_part_enabled_is_refused_before_the_workdir_is_written(tmp_path):
  from mfsample.configs.uncertainty_quality import get_config
  from mfsample.quality.runner import run_uncertainty_quality

  config = get_config("tiny")
  config.ause.enabled = False
  config.candidates.enabled = False
  with pytest.raises(ValueError, match="both False: nothing to run"):
    run_uncertainty_quality(config, str(tmp_path / "w"))
  assert not (tmp_path / "w" / "results.json").exists()


def test_paired_differences_pair_cases_with_the_other_settings_equal():
  from mfsample.quality import candidates

  assert candidates.case_name(400, "lowrank:2", 1, 3) == "steps400-lowrank2-seed1-views3"
  rows = [{"round_steps": s, "sampler": "lowrank:2", "samples": m,
           "per_case_rho_u_error": rho}
          for s, m, rho in ((150, 2, [0.1, 0.2]), (150, 8, [0.5, 0.5]),
                            (400, 2, [0.3, 0.1]), (400, 8, [0.6, 0.9]))]
  paired = candidates.paired_differences(rows, "round_steps")
  assert [(p["samples"], p["cases_above"], p["cases"]) for p in paired] == [(2, 1, 2), (8, 2, 2)]
  assert paired[0]["mean"] == pytest.approx(0.05) and paired[1]["mean"] == pytest.approx(0.25)
  assert paired[0]["sem"] == pytest.approx(np.std([0.2, -0.1], ddof=1) / np.sqrt(2))


def test_the_scene_figure_shows_every_model_of_the_scene(tmp_path):
  from mfsample.quality.figures import scene_figure
  from mfsample.testing import synthetic_views

  views, _ = synthetic_views(1, size=8, num_gaussians=5)  # (with exact depths)
  record = {"scene": "s", "seed": 0, "model": "lowrank:2", "methods": ["u"],
            "views": [{"depth_mae": 0.1, "ause": {"u": {"mae": 0.05}}}]}
  unit = {"render": views.images, "depth_error": np.random.default_rng(0).random((1, 8, 8)),
          "mask": np.ones((1, 8, 8), bool), "map_u": np.random.default_rng(1).random((1, 8, 8))}
  path = scene_figure("s", views, [record], {("s", 0, "lowrank:2"): unit},
                      str(tmp_path / "f.png"))
  assert path and os.path.getsize(path) > 0
  assert scene_figure("other", views, [record], {}, str(tmp_path / "g.png")) is None
