"""Camera parameterisations, the strategies, the optimiser, and the protocol end to end."""

import dataclasses
import functools
import json
import math
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
from conftest import float64
from planning_testlib import random_model, tiny_config, tiny_pool, trained_one_view

from mfsample import RenderSettings, jobs
from mfsample import view_uncertainty as unc
from mfsample.baselines import activenerf
from mfsample.planning import (
  optimize,
  poses,
  runner,
  strategies,
  tables,
)
from mfsample.planning.config import strategy_settings
from mfsample.planning.pool import stack_cameras
from mfsample.samplers import sample_z
from mfsample.scenes import get_scene
from mfsample.train.evaluate import mean_metrics

# ------------------------------------------------------------------ poses


def test_spherical_camera_matches_the_scene_convention():
  scene = get_scene("default")
  sphere = poses.SphereSpec.from_scene(scene, 32, 24)
  assert sphere.v_range == pytest.approx((0.01, 0.46))
  az, polar = 1.1, 0.7
  ours = poses.spherical_camera(jnp.asarray([az / (2 * math.pi), polar / math.pi]), sphere)
  ref = scene.camera_at(az, polar, 32, 24)
  np.testing.assert_allclose(ours.world_to_camera, ref.world_to_camera, atol=1e-5)
  np.testing.assert_allclose(ours.fx, ref.fx, rtol=1e-6)
  np.testing.assert_allclose(poses.camera_to_uv(ours), [az / (2 * math.pi), polar / math.pi],
                             atol=1e-5)


def test_project_uv_wraps_azimuth_and_clamps_polar():
  sphere = poses.SphereSpec(v_range=(0.01, 0.46))
  out = np.asarray(poses.project_uv(jnp.asarray([[1.25, 0.7], [-0.25, -0.1]]), sphere))
  np.testing.assert_allclose(out, [[0.25, 0.46], [0.75, 0.01]], atol=1e-6)


def test_random_uv_stays_in_the_band_and_grid_covers_it():
  sphere = poses.SphereSpec(v_range=(0.1, 0.4))
  uv = poses.random_uv(np.random.default_rng(0), 500, sphere)
  assert np.all((uv[:, 1] >= 0.1) & (uv[:, 1] <= 0.4) & (uv[:, 0] >= 0) & (uv[:, 0] < 1))
  grid, u, v = poses.uv_grid(sphere, 6, 4)
  assert grid.shape == (4, 6, 2) and v[0] == pytest.approx(0.1) and v[-1] == pytest.approx(0.4)


def test_angle_to_nearest_measures_directions_from_the_sphere_centre():
  # Cameras on a sphere around (1, 2, 0) at azimuths 0, 90 and 200 degrees on the equator.
  sphere = poses.SphereSpec(center=(1.0, 2.0, 0.0), radius=3.0)
  cams = poses.spherical_camera(jnp.asarray([[0.0, 0.5], [0.25, 0.5], [200 / 360, 0.5]]),
                                sphere)
  angle = np.degrees(poses.angle_to_nearest(cams, [0, 1], sphere.center))
  np.testing.assert_allclose(angle, [0.0, 0.0, 110.0], atol=1e-2)


def test_se3_exp_matches_the_matrix_exponential():
  with float64():
    rng = np.random.default_rng(0)
    xis = rng.normal(size=(4, 6)) * np.array([1e-7, 1e-3, 0.5, 2.0])[:, None]
    ours = np.asarray(jax.jit(poses.se3_exp)(jnp.asarray(xis)))  # batched
    for xi, mat in zip(xis, ours, strict=True):
      twist = np.zeros((4, 4))
      twist[:3, :3] = [[0, -xi[2], xi[1]], [xi[2], 0, -xi[0]], [-xi[1], xi[0], 0]]
      twist[:3, 3] = xi[3:]
      np.testing.assert_allclose(mat, scipy.linalg.expm(twist), atol=1e-12, rtol=1e-10)
    # Finite gradient at the identity, where the closed form is 0 / 0.
    g = jax.jit(jax.grad(lambda x: jnp.sum(poses.se3_exp(x) ** 2)))(jnp.zeros(6))
    assert np.all(np.isfinite(np.asarray(g)))


def test_perturb_camera_moves_in_the_camera_frame():
  cam = poses.spherical_camera(jnp.asarray([0.3, 0.3]), poses.SphereSpec())
  same = poses.perturb_camera(cam, jnp.zeros(6))
  np.testing.assert_allclose(same.world_to_camera, cam.world_to_camera, atol=1e-6)
  # A translation of +1 along the camera's z axis (forward) moves the centre forward by 1.
  moved = poses.perturb_camera(cam, jnp.asarray([0, 0, 0, 0, 0, -1.0]))
  forward = np.asarray(cam.rotation)[2]
  np.testing.assert_allclose(np.asarray(moved.center) - np.asarray(cam.center), forward,
                             atol=1e-5)


def test_downscale_camera_keeps_relative_projection():
  cam = poses.spherical_camera(jnp.asarray([0.3, 0.3]), poses.SphereSpec(width=64, height=48))
  small = poses.downscale_camera(cam, 2)
  assert (small.width, small.height) == (32, 24)
  pts = jnp.asarray([[0.1, 0.2, 0.0], [0.3, -0.2, 0.1]])
  np.testing.assert_allclose(np.asarray(small.project(pts)[0]) * 2, cam.project(pts)[0],
                             rtol=1e-5)


# ------------------------------------------------------------------ strategies


@pytest.fixture(scope="module")
def models():
  pool = tiny_pool()
  stoch = trained_one_view("lowrank")
  det = trained_one_view("deterministic")
  vmodel, losses = activenerf.fit_variance(det.model, pool.candidates.subset([0]),
                                           settings=det.settings, background=pool.background,
                                           steps=4)
  assert np.all(np.isfinite(losses))
  return {"stochastic": stoch.model, "deterministic": det.model, "variance": vmodel,
          None: None}


def _valid_camera(camera, sphere):
  w2c = np.asarray(camera.world_to_camera)
  assert camera.batch_shape == () and w2c.shape == (4, 4) and np.all(np.isfinite(w2c))
  np.testing.assert_allclose(w2c[:3, :3] @ w2c[:3, :3].T, np.eye(3), atol=1e-4)
  assert (camera.width, camera.height) == (sphere.width, sphere.height)


def _inputs(pool, config, model, views=(0, 3)):
  """A strategy's inputs with `views` (candidate indices) as the training views."""
  available = np.ones(len(pool.candidates), bool)
  available[list(views)] = False
  return strategies.Inputs(model, stack_cameras([pool.candidates.cameras[i] for i in views]),
                           pool.candidates.cameras, available, pool.sphere, pool.bounds,
                           pool.background, max_views=config.max_views)


@pytest.mark.parametrize("name", strategies.NAMES)
@pytest.mark.slow
def test_every_strategy_returns_a_valid_camera(name, models):
  pool = tiny_pool()
  config = tiny_config()
  strategy = strategies.make_strategy(name, strategy_settings(config))
  inputs = _inputs(pool, config, models[strategy.model_kind])
  available = inputs.available
  choice = strategy.select(inputs, jax.random.PRNGKey(1))
  _valid_camera(choice.camera, pool.sphere)
  assert np.isfinite(choice.score)
  if strategy.new_poses and choice.index is None:
    uv = poses.camera_to_uv(choice.camera, pool.sphere.center)
    lo, hi = pool.sphere.v_range
    assert lo - 1e-4 <= uv[1] <= hi + 1e-4
    # The score is U at the chosen pose with unscaled z, comparable with the start's.
    assert choice.score == choice.info["u_end"] > 0 and choice.info["u_start"] > 0
    dist = np.linalg.norm(np.asarray(choice.camera.center) - np.asarray(pool.sphere.center))
    assert dist == pytest.approx(pool.sphere.radius, rel=1e-4)
  else:
    # Only Ours (Opt. Best) among the new-pose strategies may answer with a candidate.
    assert not strategy.new_poses or name == "ours_opt_best"
    assert choice.index in np.nonzero(available)[0]
    np.testing.assert_allclose(choice.camera.world_to_camera,
                               pool.candidates.cameras[choice.index].world_to_camera)


# "training": only the training view itself is available, where U is lowest, so the ascent
# from it rises (2.5x on this tiny model) and a moved pose must be kept. "best": from the
# highest-U candidate, as in the protocol (either branch). lr 0: the ascent stays at the
# start, so every visited U is the start's (up to the pose's float round trip).
@pytest.mark.parametrize("start,scale_lr", [("training", 1.0), ("best", 1.0), ("best", 0.0)])
@pytest.mark.slow
def test_opt_best_keeps_the_pose_with_the_highest_selection_u(models, start, scale_lr):
  pool = tiny_pool()
  config = tiny_config()
  config.strategy.optimize.lr *= scale_lr
  config.strategy.optimize.best_every = 5
  inputs = _inputs(pool, config, models["stochastic"], views=(0,))
  if start == "training":
    inputs = inputs._replace(available=np.arange(len(pool.candidates)) == 0)
  choice = strategies.make_strategy("ours_opt_best", strategy_settings(config)).select(
      inputs, jax.random.PRNGKey(1))
  info = choice.info
  steps = config.strategy.optimize.steps
  np.testing.assert_array_equal(info["visited_steps"], strategies.visited_steps(steps, 5))
  # The start is Ours (Sel.)'s choice, scored by the same function.
  sel = strategies.make_strategy("ours_sel", strategy_settings(config)).select(
      inputs, jax.random.PRNGKey(1))
  assert info["start_index"] == sel.index and info["start_score"] == sel.score
  assert choice.score == max(sel.score, float(np.max(info["u_visited"])))
  if choice.index is None:
    assert info["kept_step"] == info["visited_steps"][np.argmax(info["u_visited"])] > 0
    # The returned camera is the visited pose that was scored, at the full image size.
    again, _ = strategies._ours_scores(inputs, strategy_settings(config).ours,
                                       stack_cameras([choice.camera]))
    np.testing.assert_allclose(again[0], choice.score, rtol=1e-5)
    _valid_camera(choice.camera, pool.sphere)
  else:
    assert info["kept_step"] == 0 and choice.index == sel.index
  if start == "training":
    assert choice.index is None and choice.score > 1.5 * sel.score
  if scale_lr == 0.0:
    np.testing.assert_allclose(info["u_visited"], sel.score, rtol=1e-6)
    assert choice.score == pytest.approx(sel.score, rel=1e-6)


def test_visited_steps():
  np.testing.assert_array_equal(strategies.visited_steps(60, 10), [10, 20, 30, 40, 50, 60])
  np.testing.assert_array_equal(strategies.visited_steps(12, 10), [10, 12])
  np.testing.assert_array_equal(strategies.visited_steps(3, 10), [3])
  with pytest.raises(ValueError, match="best_every"):
    strategies.visited_steps(60, 0)


def test_farthest_point_picks_the_farthest_candidate():
  pool = tiny_pool()
  strategy = strategies.make_strategy("farthest", strategy_settings(tiny_config()))
  inputs = strategies.Inputs(None, stack_cameras([pool.candidates.cameras[0]]),
                             pool.candidates.cameras, np.arange(8) != 0, pool.sphere,
                             pool.bounds, pool.background)
  choice = strategy.select(inputs, jax.random.PRNGKey(0))
  d = np.linalg.norm(np.asarray(pool.candidates.cameras.center)
                     - np.asarray(pool.candidates.cameras.center)[0], axis=-1)
  assert choice.index == int(np.argmax(d))


@pytest.mark.slow
def test_optimisation_increases_uncertainty_and_respects_the_band(models):
  pool = tiny_pool()
  model = models["stochastic"]
  o = tiny_config().strategy.optimize
  z = sample_z(model, int(o.samples), seed=6174)
  sphere = pool.sphere.replace(width=pool.sphere.width // o.downscale,
                               height=pool.sphere.height // o.downscale)
  opt = optimize.OptimizeSettings(steps=o.steps, lr=o.lr, z_drop_step=o.z_drop_step,
                                  z_drop_scale=o.z_drop_scale)
  uv0 = poses.camera_to_uv(pool.candidates.cameras[0])  # the training view: low U
  # Default settings, as the strategies use: the compilation is shared with their tests.
  out = optimize.optimize_spherical(model, uv0, z, sphere=sphere, opt=opt)
  values = np.asarray(out.values)
  assert values.shape == (o.steps,) and out.trajectory.shape == (o.steps + 1, 2)
  assert values[o.z_drop_step - 1] > values[0]  # before the z drop, which rescales U
  traj = np.asarray(out.trajectory)
  lo, hi = sphere.v_range
  assert np.all((traj[:, 1] >= lo - 1e-6) & (traj[:, 1] <= hi + 1e-6))
  # The 6-DoF variant runs and moves the camera.
  se3 = optimize.optimize_se3(model, poses.spherical_camera(out.params, sphere), z,
                              opt=optimize.OptimizeSettings(steps=3, z_drop_step=2),
                              settings=out.settings)
  assert np.all(np.isfinite(np.asarray(se3.params))) and np.any(np.asarray(se3.params) != 0)


@pytest.mark.slow
def test_resampled_optimisation_draws_fresh_z_from_its_key(models):
  pool = tiny_pool()
  model = models["stochastic"]
  sphere = pool.sphere.replace(width=8, height=8)
  z = sample_z(model, 2, seed=6174)
  opt = optimize.OptimizeSettings(steps=3, lr=1e-2, z_drop_step=3, resample_z=True)
  uv0 = poses.camera_to_uv(pool.candidates.cameras[4])
  with pytest.raises(ValueError, match="PRNG key"):
    optimize.optimize_spherical(model, uv0, z, sphere=sphere, opt=opt)
  run = functools.partial(optimize.optimize_spherical, model, uv0, z, sphere=sphere, opt=opt)
  a, b, c = run(key=jax.random.PRNGKey(0)), run(key=jax.random.PRNGKey(0)), run(
      key=jax.random.PRNGKey(1))
  np.testing.assert_array_equal(a.values, b.values)  # reproducible from the key
  assert np.all(np.isfinite(a.values)) and np.all(np.isfinite(c.values))
  assert a.values[0] != c.values[0]  # other z at the same start pose
  fixed = optimize.optimize_spherical(model, uv0, z, sphere=sphere,
                                      opt=dataclasses.replace(opt, resample_z=False))
  assert fixed.values[0] not in (a.values[0], c.values[0])


# ------------------------------------------------------------------ the protocol


@pytest.mark.slow
def test_protocol_runs_end_to_end_and_resumes(tmp_path):
  config = tiny_config()
  config.strategies = ("random", "ours_opt_rnd")
  results = runner.run_camera_planning(config, str(tmp_path))
  for name in ("results.json", "table.md", "cameras.png", "landscape.png", "landscape.npz"):
    assert (tmp_path / name).exists(), name
  assert set(results["summary"]) == set(config.strategies)
  for rec in results["runs"]:
    assert len(rec["indices"]) == config.max_views
    assert set(rec["metrics"]) == {"2", "3"}
    assert all(np.isfinite(rec["metrics"]["3"][k]) for k in ("psnr", "ssim"))
    if rec["strategy"] == "ours_opt_rnd":
      assert rec["indices"][1:] == [None, None]  # captured new poses
    else:
      assert len(set(rec["indices"])) == config.max_views  # no candidate twice
    # Its views in viewers' formats: nerfstudio reads them back at the record's poses.
    from mfsample.data import load_nerfstudio
    views, _ = load_nerfstudio(tmp_path / "views" / f"{rec['strategy']}-seed0")
    np.testing.assert_allclose(views.cameras.world_to_camera, rec["world_to_camera"],
                               atol=1e-6)
    assert (tmp_path / "views" / f"{rec['strategy']}-seed0" / "cameras.json").exists()
  # Every round is recorded for the viewer (mfsample.planning.rounds): the choice, and the
  # round model where the strategy has one.
  from mfsample.viewer import open_run

  steps = {s.key: s for s in open_run(tmp_path).steps()}
  assert set(steps) == {f"{n}-seed0/{v}" for n in config.strategies for v in (1, 2)}
  assert steps["random-seed0/1"].model_path is None
  opt = steps["ours_opt_rnd-seed0/2"]
  assert opt.model_path is not None and opt.proposals[0].index is None  # a new pose
  record = next(r for r in results["runs"] if r["strategy"] == "ours_opt_rnd")
  np.testing.assert_allclose(opt.proposals[0].camera.world_to_camera,
                             record["world_to_camera"][2], atol=1e-6)
  np.testing.assert_allclose(opt.train[0].world_to_camera, record["world_to_camera"][:2],
                             atol=1e-6)
  table = (tmp_path / "table.md").read_text()
  assert "Ours (Opt. Rnd.)" in table and "PSNR↑ (3 views)" in table
  assert "seconds per run" in table and set(results["run_seconds"]) == set(config.strategies)
  # A killed run resumes: finished (strategy, seed) runs are read back, not recomputed.
  run_file = tmp_path / "runs" / "random-seed0.json"
  stamp = os.path.getmtime(run_file)
  config.figures.enabled = False  # presentation only: may change between calls
  again = runner.run_camera_planning(config, str(tmp_path))
  assert os.path.getmtime(run_file) == stamp
  assert json.loads(run_file.read_text())["indices"] == again["runs"][0]["indices"]
  # More seeds go into the same workdir; only the new runs are computed.
  config.seeds = (0, 1)
  config.strategies = ("random",)
  more = runner.run_camera_planning(config, str(tmp_path))
  assert os.path.getmtime(run_file) == stamp and len(more["runs"]) == 2
  seed1 = {s.key: s for s in open_run(tmp_path).steps()}["random-seed1/2"]
  assert seed1.proposals[0].index == more["runs"][1]["indices"][2]
  assert len(more["summary"]["random"]["3"]["psnr"]["values"]) == 2
  # Finished runs of another protocol are never mixed into one table.
  config.rounds.steps += 1
  with pytest.raises(ValueError, match="different config.*rounds"):
    runner.run_camera_planning(config, str(tmp_path))


@pytest.mark.slow
def test_rounds_densify_when_their_config_asks():
  """The authors' round models: densification and lambda = 1 / views (unpadded training)."""
  config = tiny_config()
  d = config.round_train.densify
  d.start, d.every, d.stop = 20, 20, config.rounds.steps
  config.round_train.loss.volume_weight = None
  pool = tiny_pool()
  selected = [runner.candidate_view(pool, i) for i in (0, 4)]
  trained, _ = runner.Trainer(config, pool).round_state("stochastic", selected, 0,
                                                        jobs.Budgets())
  live = int(np.asarray(trained.model.mask).sum())
  assert live > config.round_train.model.init_points  # densified
  assert live <= config.round_train.model.max_gaussians
  z = sample_z(trained.model, 2)
  u = unc.uncertainty(trained.model, selected[0].camera, z).value
  assert np.isfinite(float(u)) and float(u) > 0.0
  # The paper's warm start continues one padded state, which cannot change shape.
  config.rounds.warm_start = True
  with pytest.raises(ValueError, match="cannot densify"):
    runner.Trainer(config, pool).round_state("stochastic", selected, 0, jobs.Budgets())


@pytest.mark.slow
def test_final_models_densify_when_their_config_asks():
  """The authors' final model: 3DGS with densification (variant densified_final)."""
  config = tiny_config()
  t = config.final_train
  t.train.num_steps = 30
  t.densify.start, t.densify.every, t.densify.stop = 10, 10, t.train.num_steps
  pool = tiny_pool()
  selected = [runner.candidate_view(pool, i) for i in (0, 4)]
  trainer = runner.Trainer(config, pool)
  model, budgets = trainer.final_model(selected, 0, jobs.Budgets())
  live = int(np.asarray(model.mask).sum())
  assert t.model.init_points < live <= t.model.max_gaussians
  metrics, _ = mean_metrics(model, pool.test, background=pool.background,
                            settings=budgets.get("final"))
  assert np.isfinite(metrics["psnr"])


def _workdir_with_a_run(workdir, config_dict):
  """`workdir` as an earlier call with `config_dict` left it: its config and one run."""
  (workdir / "runs").mkdir()
  (workdir / "runs" / "random-seed0.json").write_text("{}")
  (workdir / "config.json").write_text(json.dumps(config_dict))


def test_resume_guard_ignores_speed_only_fields(tmp_path):
  config = tiny_config()
  _workdir_with_a_run(tmp_path, json.loads(config.to_json_best_effort()))
  config.round_train.render.chunks_per_step = 64
  config.final_train.render.chunks_per_step = 256
  jobs.check_workdir(runner.JOB, config, str(tmp_path))  # the same runs, faster or slower
  config.final_train.render.tile_size = 8
  with pytest.raises(ValueError, match=r"differences: final_train\.render\.tile_size\)"):
    jobs.check_workdir(runner.JOB, config, str(tmp_path))


def test_table_layout_has_mean_and_std():
  records = [{"strategy": "ours_sel", "label": "Ours (Sel.)", "seed": s,
              "metrics": {"5": {"psnr": 20.0 + s, "ssim": 0.8, "lpips": 0.1}}}
             for s in (0, 1)]
  summary = tables.summarise(records, (5,))
  assert summary["ours_sel"]["5"]["psnr"]["mean"] == pytest.approx(20.5)
  assert summary["ours_sel"]["5"]["psnr"]["std"] == pytest.approx(0.5)
  table = tables.table_markdown(summary, (5,))
  assert "| Ours (Sel.) | 20.50 ± 0.50 | 0.800 ± 0.000 | 0.100 ± 0.000 |" in table


def test_paired_differences_are_per_seed_and_count_wins():
  def rec(strategy, seed, psnr, lpips):
    return {"strategy": strategy, "label": strategy.title(), "seed": seed,
            "metrics": {"10": {"psnr": psnr, "ssim": 0.8, "lpips": lpips}}}

  # A large shared seed effect (+5 dB per seed) hides a consistent +0.1 dB in mean ± std.
  records = [rec("farthest", s, 20.0 + 5 * s, 0.2) for s in range(3)]
  records += [rec("ours_sel", s, 20.1 + 5 * s, 0.3 - 0.15 * s) for s in range(3)]
  records.append(rec("ours_sel", 7, 30.0, 0.1))  # No farthest run with seed 7: not paired.
  paired = tables.paired_differences(records, (10,), "farthest")
  e = paired["ours_sel"]["10"]
  assert e["seeds"] == [0, 1, 2] and e["wins"] == 3
  assert e["mean"] == pytest.approx(0.1) and e["sem"] == pytest.approx(0.0, abs=1e-9)
  assert "farthest" not in paired
  lp = tables.paired_differences(records, (10,), "farthest", metric="lpips")["ours_sel"]["10"]
  assert lp["values"] == pytest.approx([0.1, -0.05, -0.2]) and lp["wins"] == 2  # lower wins
  labels = {"farthest": "Farthest", "ours_sel": "Ours (Sel.)"}
  table = tables.paired_markdown(paired, labels, "Farthest", (10,))
  assert "| Ours (Sel.) | +0.10 ± 0.00 (better in 3/3) |" in table
  one = tables.paired_differences(records[:1] + records[3:4], (10,), "farthest")
  assert one["ours_sel"]["10"]["sem"] is None


@pytest.mark.slow
def test_batched_evaluation_matches_the_training_module(models):
  from mfsample.train.evaluate import evaluate

  pool = tiny_pool()
  settings = RenderSettings(max_intersections=1 << 11)
  ours, _ = mean_metrics(models["deterministic"], pool.test,
                         background=pool.background, settings=settings)
  ref = evaluate(models["deterministic"], pool.test, background=pool.background,
                 settings=settings)
  assert ours["psnr"] == pytest.approx(ref.metrics["psnr"], rel=1e-4)
  assert ours["ssim"] == pytest.approx(ref.metrics["ssim"], rel=1e-4)


def test_optimisation_summary_counts_rounds_and_kept_poses():
  opt = [{}, {"u_start": 2.0, "u_end": 1.0}, {"u_start": 1.0, "u_end": 3.0}]
  best = [{}, {"u_start": 2.0, "u_end": 1.0, "kept_step": 0, "start_score": 4.0,
               "u_visited": [3.0, 1.0]},
          {"u_start": 1.0, "u_end": 3.0, "kept_step": 20, "start_score": 4.0,
           "u_visited": [3.0, 6.0]}]
  records = [{"strategy": "ours_opt_sel", "optimisation": opt},
             {"strategy": "ours_opt_best", "optimisation": best},
             {"strategy": "farthest", "optimisation": [{}, {}, {}]}]
  summary = tables.optimisation_summary(records + records[:1])
  assert set(summary) == {"ours_opt_sel", "ours_opt_best"}
  assert summary["ours_opt_sel"] == {"rounds": 4, "u_rose": 2, "u_end_over_start": 1.75}
  assert summary["ours_opt_best"] == {"rounds": 2, "u_rose": 1, "u_end_over_start": 1.75,
                                      "kept_moved": 1, "kept_steps": {"0": 1, "20": 1},
                                      "kept_over_start": 1.25}
  table = tables.optimisation_markdown(summary, {"ours_opt_sel": "O", "ours_opt_best": "B"})
  assert "| O | 4 | 2 | 1.750 | - | - |" in table and "| B | 2 | 1 | 1.750 | 1 | 1.250 |" in table


def test_seconds_summary_spreads_runs_and_rounds_after_the_first():
  records = [{"strategy": "ours_sel", "seconds": 30.0, "round_seconds": [0.0, 4.0, 8.0]},
             {"strategy": "ours_sel", "seconds": 10.0, "round_seconds": [0.0, 2.0]},
             {"strategy": "ours_sel", "seconds": 20.0, "round_seconds": [0.0, 6.0]},
             {"strategy": "farthest", "seconds": 5.0, "round_seconds": [0.0]}]
  summary = tables.seconds_summary(records)
  assert summary["ours_sel"] == {"runs": 3, "run": {"min": 10.0, "median": 20.0, "max": 30.0},
                                 "round": {"min": 2.0, "median": 5.0, "max": 8.0}}
  assert summary["farthest"] == {"runs": 1, "run": {"min": 5.0, "median": 5.0, "max": 5.0}}
  table = tables.seconds_markdown(summary, {"ours_sel": "S", "farthest": "F"})
  assert "| F | 1 | 5 / 5 / 5 | - |" in table and "| S | 3 | 10 / 20 / 30 | 2 / 5 / 8 |" in table


@pytest.mark.parametrize("field, value, message", [
    ("rounds.downscale", 5, r"config.rounds.downscale = 5: the pool's images are 24 x 24 "
     r"pixels \(config.data.width x height\), which it must divide"),
    ("strategy.score_downscale", 25, r"config.strategy.score_downscale = 25: .* must be <= 24"),
    ("strategy.optimize.downscale", 30, r"config.strategy.optimize.downscale = 30"),
])
def test_sizes_the_images_cannot_take_are_refused_before_anything_trains(field, value,
                                                                          message, tmp_path):
  """Rules of the config against the pool's image size: at validation where the config gives
  the size, once the pool is loaded for files (`check_image_size` with its path)."""
  from mfsample.config_checks import ConfigError
  from mfsample.planning.config import check_image_size

  config = tiny_config()
  block, leaf = field.rsplit(".", 1)
  node = config
  for part in block.split("."):
    node = node[part]
  node[leaf] = value
  with pytest.raises(ConfigError, match=message):
    runner.run_camera_planning(config, str(tmp_path / "w"))
  assert not (tmp_path / "w").exists()
  with pytest.raises(ConfigError, match=r"\(the dataset at data/lego\)"):
    check_image_size(config, 24, 24, "data/lego")
  check_image_size(config, 480, 480, "data/lego")


# ------------------------------------------------------------------ pieces (the fast tier)


def test_u_against_error_scores_candidates_and_ranks_their_error(tmp_path):
  """`u_error.u_against_error` on an untrained model and three 8 x 8 candidates: U of each
  (positive: B_hat spreads the Gaussians), the error only with images, the angle only with
  training cameras; the landscape figure of such U values is written."""
  from mfsample import orbit_camera
  from mfsample.planning.figures import landscape_figure
  from mfsample.planning.u_error import u_against_error

  model = random_model(num=20)
  cams = stack_cameras([orbit_camera(a, 0.3, width=8, height=8, distance=3.0)
                        for a in (0.0, 2.0, 4.0)])
  z = sample_z(model, 2)
  plain = u_against_error(model, cams, z, background=jnp.zeros(3))
  assert plain.u.shape == (3,) and np.all(plain.u > 0)
  assert plain.error is None and plain.angle is None and plain.rho_u_error is None
  images = np.zeros((3, 8, 8, 3), np.float32)
  full = u_against_error(model, cams, z, background=jnp.zeros(3), images=images,
                         train_cameras=stack_cameras([orbit_camera(0.0, 0.3, width=8,
                                                                   height=8, distance=3.0)]))
  np.testing.assert_allclose(full.u, plain.u, rtol=1e-6)
  assert full.error.shape == (3,) and np.all(full.error > 0)
  assert full.angle[0] == pytest.approx(0.0, abs=1e-3) and full.angle[1] > 0.5
  land = {"values": np.outer([1.0, 2.0], plain.u), "u": [0.0, 0.5, 0.9], "v": [0.3, 0.6],
          "train_uv": [[0.0, 0.4]], "trajectory": [[0.2, 0.5], [0.5, 0.45]]}
  path = landscape_figure(land, str(tmp_path / "land.png"))
  assert os.path.getsize(path) > 0
