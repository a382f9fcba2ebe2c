"""The relightable field, U over lights, the light strategies and the light-planning protocol.

Everything runs on the tiny variant of configs/light_planning.py (a synthetic diffuse shell
at 24 x 24, n = 4 light coefficients); the compiled functions are shared through the
library's module-level jits.
"""

import functools
import json
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import float64

from configs import light_planning
from mfsample import config_checks
from mfsample.config_blocks import data_spec
from mfsample.data.datasets import load_light_data, scene_extent
from mfsample.lighting import captures, field, lights, protocol, strategies, training
from mfsample.lighting import optimize as opt_lib
from mfsample.lighting import uncertainty as lu
from mfsample.lighting.config import light_recipe
from mfsample.lighting.config import validate as validate_lighting
from mfsample.renderer import RenderSettings
from mfsample.samplers import SamplerSpec, sample_z

N = 4  # light coefficients of the tiny variant
SETTINGS = RenderSettings(max_intersections=1 << 12)


def tiny():
  return light_planning.get_config("tiny")


@functools.cache
def tiny_data():
  return load_light_data(data_spec(tiny().data), N)


def tiny_start(config, data, steps):
  """(`TrainSetup`, step-0 state) of the light protocol's field on `data`, for `steps` steps
  in all."""
  recipe = light_recipe(config, scene_extent(data.train_cameras))
  recipe = recipe._replace(settings=recipe.settings.replace(num_steps=steps))
  return training.start(recipe, int(config.seed), data.bounds)


def cameras():
  return captures.to_device_cameras(tiny_data().train_cameras)


@functools.cache
def random_model(kind="lowrank", out_coeffs=1, dtype=jnp.float32, seed=0):
  """An untrained relightable model on the tiny scene's box with random T and B_hat entries
  of ~0.05 over T (so that U depends on the light without training)."""
  rng = np.random.default_rng(seed)
  data = tiny_data()
  points = rng.uniform(data.bounds[0] * 0.8, data.bounds[1] * 0.8, (120, 3))
  groups = ("transfer_dc",) if kind != "deterministic" else ()
  spec = SamplerSpec(kind=kind, rank=2, groups=groups, bounds=(("transfer_dc", 0.5),))
  model = field.init_relightable(jax.random.PRNGKey(seed), points, spec=spec,
                                 out_coeffs=out_coeffs, light_coeffs=N,
                                 init_scales={"transfer_dc": 0.05}, init_opacity=0.6)
  mean = dict(model.params.mean)
  for g in ("transfer_dc", "transfer_rest"):
    if g in mean:
      mean[g] = jnp.asarray(rng.uniform(-0.2, 0.4, mean[g].shape), jnp.float32)
  model = model.replace(params=model.params._replace(mean=mean))
  cast = lambda x: x.astype(dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x
  return jax.tree.map(cast, model)


def u_of(model, xi, cams=None, z=None):
  cams = cameras() if cams is None else cams
  z = sample_z(model, 2, seed=6174) if z is None else z
  return float(lu.light_uncertainty(model, cams, z, jnp.asarray(xi), settings=SETTINGS).value)


# ------------------------------------------------------------------ the field


@pytest.mark.slow
def test_radiance_is_linear_in_the_light_and_matches_the_basis_renders():
  model = random_model(out_coeffs=4)
  dirs = jnp.asarray(np.random.default_rng(1).normal(size=(model.capacity, 3)), jnp.float32)
  dirs = dirs / jnp.linalg.norm(dirs, axis=-1, keepdims=True)
  a, b = jnp.array([1.0, -0.5, 0.3, 2.0]), jnp.array([0.2, 0.1, -1.0, 0.4])
  cam = cameras()[0]

  @jax.jit
  def parts(raw, mask):
    combined = field.radiance(raw, 2.0 * a - 3.0 * b, dirs)
    separate = 2.0 * field.radiance(raw, a, dirs) - 3.0 * field.radiance(raw, b, dirs)
    from_basis = jnp.einsum("cbk,b->ck", field.basis_radiance(raw, dirs), a)
    images, _ = field.render_basis(raw, mask, cam, settings=SETTINGS)
    direct = field.render_relit(raw, mask, a, cam, settings=SETTINGS).rgb
    return (combined, separate, from_basis, field.radiance(raw, a, dirs),
            jnp.einsum("hwbc,b->hwc", images, a), direct)

  combined, separate, from_basis, radiance, relit, direct = parts(model.params.mean, model.mask)
  np.testing.assert_allclose(combined, separate, atol=1e-5)
  np.testing.assert_allclose(from_basis, radiance, atol=1e-5)
  # One render with n x 3 features gives the image under any light (compositing is linear).
  np.testing.assert_allclose(relit, direct, atol=1e-5)
  assert float(jnp.max(jnp.abs(direct))) > 0.05
  assert "sh_dc" not in model.params.mean and field.coefficient_counts(model) == (4, N)


def test_densification_moves_transfer_rows_with_their_gaussians():
  from mfsample.train import densify

  setup, state = tiny_start(tiny(), tiny_data(), 100)
  live = state.model.num_live
  t = np.asarray(state.model.params.mean["transfer_dc"]).copy()
  t[:live] = np.arange(live)[:, None, None, None]  # each row tagged by its index
  mean = dict(state.model.params.mean, transfer_dc=jnp.asarray(t))
  state = state._replace(model=state.model.replace(params=state.model.params._replace(
      mean=mean)))
  grads = np.zeros(state.model.capacity, np.float32)
  grads[:5] = 1.0  # five Gaussians to densify
  stats = state.stats._replace(grad_accum=jnp.asarray(grads),
                               count=jnp.ones(state.model.capacity, jnp.int32))
  new, report = densify.densify_and_prune(
      state._replace(stats=stats), rng=np.random.default_rng(0), grad_threshold=0.5,
      percent_dense=0.01, extent=setup.extent, min_opacity=0.0, init_scales=setup.init_scales,
      max_gaussians=10_000)
  assert report.cloned + report.split == 5 and report.live == live + report.cloned + report.split
  out = np.asarray(new.model.params.mean["transfer_dc"])
  kept = out[:report.live, 0, 0, 0]
  # Survivors keep their tags; the copies carry their parents' tags (0..4).
  assert set(np.round(kept[-(report.cloned + 2 * report.split):])) <= set(range(5))
  assert new.model.params.b_hat["transfer_dc"].shape[1:] == (1, N, 3, 2)


@pytest.mark.slow
def test_a_batch_of_light_view_pairs_trains_like_its_pairs_one_by_one():
  """The relightable field with B = 2 (light, view) pairs per step (`train.step`'s batch):
  the data term is the mean of the two pairs' single steps' and the densification counts
  add up."""
  import dataclasses

  from mfsample.train import step as step_lib

  data = tiny_data()
  setup, state = tiny_start(tiny(), data, 100)
  used = np.eye(N)[:2] * lights.UNIFORM_NORM
  images = jnp.asarray(np.stack([captures.capture(data.train_basis, x) for x in used]))
  inputs = (images, jnp.asarray(used, jnp.float32), cameras())
  pairs = [(0, 1), (1, 2)]  # (light slot, view)
  rows = setup.sobol[:2]
  one = step_lib.make_train_step(setup.step_config, setup.field)
  singles = [one(state, inputs, (jnp.asarray([light], jnp.int32),
                                 jnp.asarray([view], jnp.int32)), rows[i:i + 1].reshape(1, 1, -1))
             for i, (light, view) in enumerate(pairs)]
  batch_cfg = dataclasses.replace(setup.step_config, batch_size=2)
  batch = step_lib.make_train_step(batch_cfg, setup.field)
  index = tuple(jnp.asarray(x, jnp.int32) for x in zip(*pairs, strict=True))
  new, metrics = batch(state, inputs, index, rows.reshape(2, 1, -1))
  assert not bool(metrics.overflow) and int(new.step) == 1
  np.testing.assert_allclose(float(metrics.data_loss),
                             np.mean([float(m.data_loss) for _, m in singles]), rtol=1e-6)
  np.testing.assert_array_equal(new.stats.count,
                                singles[0][0].stats.count + singles[1][0].stats.count)
  assert int(np.sum(new.stats.count)) > 0


# ------------------------------------------------------------------ U over lights


def test_u_is_a_quadratic_form_of_the_light():
  model = random_model()
  z = sample_z(model, 2, seed=6174)
  gram, _ = lu.light_gram(model, cameras(), z, settings=SETTINGS)
  q = np.asarray(gram.q, np.float64)
  xi = np.array([2.0, -0.7, 0.4, 1.1])
  u = u_of(model, xi, z=z)
  assert u > 0
  for c in (0.5, -2.0, 3.0):  # U(c xi) = c^2 U(xi)
    np.testing.assert_allclose(u_of(model, c * xi, z=z), c * c * u, rtol=2e-5)
  np.testing.assert_allclose(lu.quadratic_u(q, xi), u, rtol=2e-5)
  for j in range(N):  # the one-hot lights are Q's diagonal
    e = np.eye(N)[j] * lights.UNIFORM_NORM
    np.testing.assert_allclose(u_of(model, e, z=z), lights.UNIFORM_NORM ** 2 * q[j, j],
                               rtol=2e-5)
  assert np.all(np.linalg.eigvalsh(q) > -1e-9 * np.abs(q).max())  # PSD


@pytest.mark.slow
def test_u_gradient_matches_finite_differences_in_float64():
  with float64():
    model = random_model(dtype=jnp.float64)
    cams = jax.tree.map(lambda x: jnp.asarray(x, jnp.float64), cameras())
    z = sample_z(model, 2, seed=6174)
    xi = jnp.asarray([1.5, -0.4, 0.8, 0.3], jnp.float64)

    def u(x):
      return lu.light_uncertainty(model, cams, z, x, settings=SETTINGS).value

    grad = np.asarray(jax.grad(u)(xi))
    h = 1e-4
    fd = np.array([(u(xi + h * e) - u(xi - h * e)) / (2 * h) for e in np.eye(N)])
    np.testing.assert_allclose(grad, fd, rtol=1e-7, atol=1e-12)
    gram, _ = lu.light_gram(model, cams, z, settings=SETTINGS)
    np.testing.assert_allclose(grad, 2.0 * np.asarray(gram.q) @ np.asarray(xi), rtol=1e-9)
    assert np.abs(grad).max() > 0


def test_a_deterministic_model_has_zero_u():
  model = random_model(kind="deterministic")
  z = sample_z(model, 2, seed=6174)
  assert u_of(model, [3.0, 1.0, -1.0, 0.5], z=z) == 0.0


# ------------------------------------------------------------------ strategies


def _inputs(model, used):
  z = sample_z(model, 2, seed=6174)
  gram, _ = lu.light_gram(model, cameras(), z, settings=SETTINGS)
  return strategies.LightInputs(
      model=model, cameras=cameras(), z=z, q=np.asarray(gram.q, np.float64),
      used=np.asarray(used), index=len(used), norm=lights.UNIFORM_NORM,
      ascent=opt_lib.AscentSettings(steps=40, lr=0.3, final_lr=0.01),
      renders=strategies.LightRenders(u=SETTINGS))


@pytest.mark.slow
def test_ascent_beats_the_best_one_hot_and_reaches_the_top_eigenvector():
  model = random_model()
  inputs = _inputs(model, [lights.uniform_light(N)])
  choice = strategies.make_light_strategy("ours").select(inputs, jax.random.PRNGKey(0))
  top, _ = lu.top_eigen(inputs.q)
  u_max = lights.UNIFORM_NORM ** 2 * top
  u_end = lu.quadratic_u(inputs.q, choice.light)
  assert choice.info["u_one_hot"] < 0.99 * u_max  # the start is not already the optimum
  assert u_end >= choice.info["u_one_hot"]
  assert u_end >= 0.99 * u_max
  # The ascent's own U (rendered under the light) agrees with the quadratic form.
  np.testing.assert_allclose(choice.info["u_end"], u_end, rtol=1e-4)


@pytest.mark.slow
def test_every_strategy_returns_a_light_of_the_common_norm():
  model = random_model()
  used = np.stack([lights.uniform_light(N), lights.on_sphere([0.1, 1.0, 0.0, 0.0])])
  inputs = _inputs(model, used)
  top, vector = lu.top_eigen(inputs.q)
  chosen = {}
  for name in strategies.NAMES:
    choice = strategies.make_light_strategy(name).select(inputs, jax.random.PRNGKey(3))
    light = choice.light
    assert light.shape == (N,) and np.all(np.isfinite(light)), name
    np.testing.assert_allclose(np.linalg.norm(light), lights.UNIFORM_NORM, rtol=1e-9)
    assert light[0] >= 0.0, name  # the brighter of xi and -xi
    chosen[name] = light
  np.testing.assert_allclose(np.abs(used @ chosen["orthogonal"]), 0.0, atol=1e-9)
  np.testing.assert_allclose(np.abs(chosen["ours_exact"] @ vector), lights.UNIFORM_NORM,
                             rtol=1e-9)
  # Seeded: the same key gives the same random light, the next Sobol index another point.
  again = strategies.make_light_strategy("random").select(inputs, jax.random.PRNGKey(3))
  np.testing.assert_array_equal(again.light, chosen["random"])
  later = strategies.make_light_strategy("sobol").select(inputs._replace(index=3), None)
  assert not np.allclose(later.light, chosen["sobol"])


def test_bad_lights_get_clear_errors():
  model = random_model()
  z = sample_z(model, 2, seed=6174)
  with pytest.raises(ValueError, match=r"one SH light of 4 coefficients \(shape \[4\]\), got "
                     r"shape \[3\]"):
    lu.light_uncertainty(model, cameras(), z, [1.0, 2.0, 3.0], settings=SETTINGS)
  with pytest.raises(ValueError, match=r"non-finite coefficients at \[1, 3\]"):
    lu.light_uncertainty(model, cameras(), z, [1.0, np.nan, 0.0, np.inf], settings=SETTINGS)
  with pytest.raises(ValueError, match="shape \\[4\\]"):
    captures.capture(tiny_data().train_basis, np.ones((4, 3)))
  with pytest.raises(ValueError, match="xi0 has non-finite"):
    opt_lib.ascend(model, cameras(), z, [np.nan, 0, 0, 0], opt=opt_lib.AscentSettings(),
                   settings=SETTINGS)
  with pytest.raises(ValueError, match="zero light has no direction"):
    lights.on_sphere(np.zeros(N))
  with pytest.raises(ValueError, match="lights\\[1\\] has non-finite"):
    lights.check_lights([[1, 0, 0, 0], [0, np.inf, 0, 0]], N)
  with pytest.raises(ValueError, match="out_coeffs \\(m\\) must be one of"):
    field.group_shapes(3, 16)
  with pytest.raises(ValueError, match="unknown light strategy 'oracle'"):
    strategies.make_light_strategy("oracle")


@pytest.mark.parametrize("variant", ["", "tiny"])
def test_the_config_file_loads_from_the_command_line(variant):
  import pathlib

  from absl import flags
  from ml_collections import config_flags

  path = pathlib.Path(__file__).resolve().parents[2] / "configs" / "light_planning.py"
  argv = ["prog", f"--config={path}:{variant}" if variant else f"--config={path}",
          "--config.num_lights=4", "--config.planning.ascent_steps=7"]
  fv = flags.FlagValues()
  config_flags.DEFINE_config_file("config", None, "", flag_values=fv, lock_config=True,
                                  sys_argv=argv)
  fv(argv)
  config = fv.config
  assert config.num_lights == 4 and config.planning.ascent_steps == 7
  assert config.data.kind == {"": "scene", "tiny": "synthetic"}[variant]
  validate_lighting(config)
  with pytest.raises(AttributeError):
    config.num_light = 3  # locked: typos are errors
  with pytest.raises(ValueError, match="unknown variant 'huge'"):
    light_planning.get_config("huge")


def test_the_config_is_checked_on_entry_naming_the_field():
  config = tiny()
  config.num_lights = 6  # > n = 4 with the orthogonal strategy
  with pytest.raises(config_checks.ConfigError, match="config.num_lights = 6"):
    validate_lighting(config)
  config = tiny()
  config.strategies = ("ours", "best")
  with pytest.raises(config_checks.ConfigError, match="config.strategies: 'best'"):
    validate_lighting(config)
  config = tiny()
  config.planning.ascent_final_lr = 1.0
  with pytest.raises(config_checks.ConfigError, match="planning.ascent_final_lr"):
    validate_lighting(config)
  config = tiny()
  config.planning.downscale = config.data.width + 1  # a render under one pixel
  with pytest.raises(config_checks.ConfigError, match=rf"config.planning.downscale = "
                     rf"{config.data.width + 1}: the images are"):
    validate_lighting(config)


# ------------------------------------------------------------------ training


@pytest.mark.slow
def test_a_field_trained_on_all_basis_lights_reproduces_a_held_out_light():
  """A diffuse field trained 400 steps on the n one-hot lights (at the common norm) renders its
  training views under a held-out environment light at >= 25 dB PSNR (clamped images), and
  >= 8 dB above the exact image under that light's DC part alone, which is the best that a
  field knowing only the uniform light could do (15.6 dB here)."""
  from mfsample.lighting import evaluate

  config = tiny()
  steps = 400
  data = tiny_data()
  cams = cameras()
  used = np.eye(N) * lights.UNIFORM_NORM
  held_out, _ = lights.held_out_lights(N, num_environments=1, num_random=0, seed=5)
  truth = captures.capture(data.train_basis, held_out[0])
  dc_only = captures.capture(data.train_basis, held_out[0] * (np.arange(N) == 0))
  setup, state = tiny_start(config, data, steps)
  images = np.stack([captures.capture(data.train_basis, x) for x in used])
  res = training.train_steps(setup, state, jnp.asarray(images),
                             jnp.asarray(used, jnp.float32), cams, num_lights=N,
                             phase_start=0, end=steps, max_traces=1)
  assert int(res.state.step) == steps
  pred, _ = evaluate.relight_views(res.state.model, cams, held_out, settings=SETTINGS)
  psnr = float(np.mean(evaluate.image_metrics(pred[0], truth)["psnr"]))
  baseline = float(np.mean(evaluate.image_metrics(dc_only, truth)["psnr"]))
  assert psnr >= 25.0, (psnr, baseline)
  assert psnr >= baseline + 8.0, (psnr, baseline)


# ------------------------------------------------------------------ the protocol


@pytest.mark.slow
def test_the_tiny_experiment_runs_end_to_end_and_resumes(tmp_path, monkeypatch):
  config = tiny()
  done = protocol.run_light_planning(config, str(tmp_path / "a"))
  for name in ("results.json", "table.md", "metrics.png", "relit.png", "u_sphere.png"):
    assert (tmp_path / "a" / name).exists(), name
  summary = done["summary"]
  assert set(summary) == set(strategies.NAMES)
  for s in summary.values():
    assert set(s["by_lights"]) == {"1", "2", "3"}
    assert all(np.isfinite(s["by_lights"][k]["psnr"]) for k in s["by_lights"])
  np.testing.assert_allclose(summary["ours_exact"]["u_ratio"], 1.0, rtol=1e-9)
  assert min(summary["ours"]["u_ratio"]) > 0.9
  assert "| Ours (exact) |" in (tmp_path / "a" / "table.md").read_text()
  # The viewer (mfsample.viewer) reads every choice back, with the Q that made it.
  from mfsample.viewer import open_run

  steps = {s.key: s for s in open_run(tmp_path / "a").steps()}
  assert set(steps) == {"shared"} | {f"{n}/{k}" for n in strategies.NAMES for k in (2, 3)}
  np.testing.assert_allclose(steps["shared"].q, done["shared"]["q"])
  ours = next(r for r in done["runs"] if r["strategy"] == "ours")["phases"]
  np.testing.assert_allclose(steps["ours/3"].q, ours[1]["q"])
  np.testing.assert_allclose(steps["ours/3"].next_light[1], ours[1]["light"])
  assert steps["ours/2"].model_path is not None and steps["ours/3"].model_path is None

  # A run killed after the first light of Sobol resumes there and ends where the
  # uninterrupted run ended; finished strategies are loaded, not recomputed.
  calls = {"n": 0}
  save = training.save_state

  def killed(directory, *args, **kwargs):
    path = save(directory, *args, **kwargs)
    if directory.endswith(os.path.join("runs", "sobol")):
      calls["n"] += 1
      raise KeyboardInterrupt
    return path

  monkeypatch.setattr(training, "save_state", killed)
  with pytest.raises(KeyboardInterrupt):
    protocol.run_light_planning(config, str(tmp_path / "b"))
  assert calls["n"] == 1
  running = {s.key: s for s in open_run(tmp_path / "b").steps()}
  assert {"sobol/2", "sobol/trained2"} <= set(running)  # the killed strategy's latest phase
  assert running["sobol/trained2"].model_path is not None
  monkeypatch.setattr(training, "save_state", save)
  trained = {"n": 0}
  train_steps = training.train_steps

  def counted(*args, **kwargs):
    trained["n"] += 1
    return train_steps(*args, **kwargs)

  monkeypatch.setattr(training, "train_steps", counted)
  resumed = protocol.run_light_planning(config, str(tmp_path / "b"))
  # random and the first Sobol phase were done: Sobol's last, then 3 strategies x 2 lights.
  assert trained["n"] == 1 + 3 * 2
  for name in strategies.NAMES:
    for k in ("1", "2", "3"):
      assert resumed["summary"][name]["by_lights"][k]["psnr"] == pytest.approx(
          summary[name]["by_lights"][k]["psnr"], abs=1e-4), (name, k)

  changed = tiny()
  changed.steps_per_light = 31
  with pytest.raises(ValueError, match="differences: steps_per_light"):
    protocol.run_light_planning(changed, str(tmp_path / "b"))
  with open(tmp_path / "b" / "results.json") as f:
    assert json.load(f)["num_lights"] == 3


# ------------------------------------------------------------------ pieces (the fast tier)


def test_light_slots_hold_the_used_lights_and_pad_with_dark_slots():
  """`protocol.light_slots`: slot i holds the captures under the i-th used light, the
  remaining slots are zeros (never drawn)."""
  import types

  basis = np.random.default_rng(0).random((2, 4, 3, 3, 3)).astype(np.float32)  # [V, n, ...]
  ctx = types.SimpleNamespace(config=types.SimpleNamespace(num_lights=3),
                              data=types.SimpleNamespace(light_coeffs=4, train_basis=basis))
  used = np.array([lights.uniform_light(4)])
  images, slots = protocol.light_slots(ctx, used)
  assert images.shape == (3, 2, 3, 3, 3) and slots.shape == (3, 4)
  np.testing.assert_allclose(images[0], captures.capture(basis, used[0]), rtol=1e-6)
  assert not np.any(np.asarray(images[1:])) and not np.any(np.asarray(slots[1:]))


def test_image_metrics_and_the_tables_of_a_summary():
  """20 dB for a uniform error of 0.1; the tables put the shared first light in column 1
  of every strategy and a dash where a strategy has no figure."""
  from mfsample.lighting import evaluate, tables

  gt = np.full((2, 12, 12, 3), 0.5, np.float32)
  metrics = evaluate.image_metrics(gt + 0.1, gt)
  np.testing.assert_allclose(metrics["psnr"], 20.0, rtol=1e-5)
  assert metrics["lpips"] is None and np.all(metrics["ssim"] < 1.0)
  shared = {"metrics": {"psnr": 20.0}, "train_seconds": 1.0}
  records = [{"strategy": "random", "label": "Random", "phases": [
      {"lights": 2, "metrics": {"psnr": 21.5}, "u_ratio": 0.5, "plan_seconds": 0.1,
       "train_seconds": 2.0}]}]
  summary = tables.summarise(shared, records)
  assert summary["random"]["train_seconds"] == [1.0, 2.0]
  table = tables.by_lights_markdown(summary, 3)
  assert table.splitlines()[2] == "| Random | 20.00 | 21.50 | - |"


def test_u_over_directions_is_the_quadratic_form_of_each_point_light():
  """U of the point light from every grid direction is xi^T Q xi; with Q = e_0 e_0^T (the
  constant band only) it is the same from everywhere."""
  from mfsample.lighting.figures import u_over_directions

  q = np.zeros((4, 4))
  q[0, 0] = 1.0
  u, dirs = u_over_directions(q, 2.0, 4, 8)
  assert u.shape == (4, 8) and dirs.shape == (4, 8, 3)
  np.testing.assert_allclose(u, u.flat[0], rtol=1e-6)
  assert u.flat[0] > 0
