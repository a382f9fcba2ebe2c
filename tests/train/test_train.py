"""Tests of the training step, densification, the loop, checkpoints and resumption."""

import dataclasses
import functools
import json
import os

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import tiny_config, tiny_start, train_with

from mfsample import config_blocks, samplers
from mfsample._json import without_fields
from mfsample.data import datasets as data_lib
from mfsample.data.ply import load_ply
from mfsample.model import sample
from mfsample.renderer import render
from mfsample.train import checkpoint as ckpt
from mfsample.train import densify as densify_lib
from mfsample.train import evaluate as eval_lib
from mfsample.train import loop, losses
from mfsample.train import step as step_lib
from mfsample.train.experiment import train_and_evaluate
from mfsample.train.step import make_train_step

KINDS = ("deterministic", "diagonal", "block", "lowrank")


class Run:
  """A sampler's setup, initial state and jitted step on the tiny scene."""

  def __init__(self, config, dataset, max_traces=None):
    self.config = config
    self.views = data_lib.to_device(dataset.train)
    self.plan, model = tiny_start(config, dataset)
    self.setup = loop.make_setup(self.plan.settings, model, seed=int(config.seed),
                                 extent=self.plan.extent, num_views=len(self.views))
    self.state0 = loop.init_state(model, self.setup)
    self.fn = make_train_step(self.setup.step_config, max_traces=max_traces)

  def step(self, state):
    return self.fn(state, (self.views.images, self.views.cameras),
                   *loop.step_targets(self.setup, int(state.step), len(self.views)))


@pytest.fixture(scope="module")
def runs(tiny_dataset):
  out = {}
  for kind in KINDS:
    # The low-rank step is wrapped in chex.assert_max_traces(n=1): every test that steps
    # it (several, with many states) shows that it never retraces.
    out[kind] = Run(tiny_config(kind), tiny_dataset, max_traces=1 if kind == "lowrank" else None)
  return out


def _mean_loss(model, views, background, settings):
  res = eval_lib.evaluate(model, views, background=background, settings=settings)
  return float(np.mean([-p for p in res.per_view["psnr"]])), res


@pytest.mark.parametrize("kind", KINDS)
def test_one_training_step_per_sampler(runs, kind):
  run = runs[kind]
  state, metrics = run.step(run.state0)
  assert int(state.step) == 1 and not bool(metrics.overflow)
  assert np.isfinite(float(metrics.loss)) and float(metrics.data_loss) > 0
  live = np.asarray(state.model.mask)
  for g, new in state.model.params.mean.items():
    if g == "quats":  # isotropic initial Gaussians: rotations get no gradient yet
      continue
    old = np.asarray(run.state0.model.params.mean[g])
    assert not np.array_equal(np.asarray(new)[live], old[live]), g
  if kind == "deterministic":
    assert state.model.params.b_hat == {}
  else:
    for g, new in state.model.params.b_hat.items():
      new = np.asarray(new)
      assert not np.array_equal(new[live], np.asarray(run.state0.model.params.b_hat[g])[live])
      assert new.min() >= 0.0 and new.max() <= run.plan.spec.bound(g)
  chex.assert_tree_all_finite(state)


def test_loss_decreases_without_retracing(runs, tiny_dataset):
  run = runs["lowrank"]
  settings = run.setup.step_config.settings
  before, _ = _mean_loss(run.state0.model, tiny_dataset.train, tiny_dataset.background,
                         settings)
  state = run.state0
  for _ in range(36):
    state, metrics = run.step(state)  # 36 states, 12 views: assert_max_traces(n=1) holds
    assert not bool(metrics.overflow)
  after, _ = _mean_loss(state.model, tiny_dataset.train, tiny_dataset.background, settings)
  assert after < before - 2.0, (before, after)  # mean train PSNR up by more than 2 dB


def test_volume_term_grows_b_hat(runs):
  """On volume steps the loss is data - lambda ||B_hat||_1 and B_hat entries grow."""
  run = runs["lowrank"]
  state = run.state0
  for _ in range(10):
    state, metrics = run.step(state)
  # Step index 9 is a volume step (every 10th); the loss includes -lambda * volume there.
  lam = run.setup.step_config.volume_weight
  np.testing.assert_allclose(float(metrics.loss),
                             float(metrics.data_loss) - lam * float(metrics.volume), rtol=1e-5)
  assert float(losses.volume(state.model)) > float(losses.volume(run.state0.model))


def test_padding_never_changes_a_render_nor_receives_updates(runs):
  run = runs["lowrank"]
  state = run.state0
  model = state.model
  live = np.asarray(model.mask)
  pad = jnp.asarray(~live)

  def wild(x, value):  # extreme but finite values on padding rows only
    return jnp.where(pad.reshape((-1,) + (1,) * (x.ndim - 1)), jnp.asarray(value, x.dtype), x)

  mean = dict(model.params.mean)
  mean["means"] = wild(mean["means"], 0.0)  # right in front of every camera
  mean["opacity_logits"] = wild(mean["opacity_logits"], 10.0)
  mean["log_scales"] = wild(mean["log_scales"], 0.0)
  mean["sh_dc"] = wild(mean["sh_dc"], 3.0)
  spread = {g: wild(v, 0.3) for g, v in model.params.b_hat.items()}
  signs = {g: wild(v, 1) for g, v in model.signs.items()}
  wild_model = model.replace(params=model.params._replace(mean=mean, b_hat=spread),
                             signs=signs)
  camera = run.views.cameras[0]
  z = jnp.asarray(samplers.sobol_z(1, 2, seed=0)[0])
  settings = run.setup.step_config.settings
  ref = render(sample(model, z), camera, settings=settings)
  out = render(sample(wild_model, z), camera, settings=settings)
  np.testing.assert_array_equal(np.asarray(out.rgb), np.asarray(ref.rgb))

  wild_state = state._replace(model=wild_model)
  for _ in range(3):
    wild_state, _ = run.step(wild_state)
  for before, after in zip(jax.tree.leaves(wild_model.params),
                           jax.tree.leaves(wild_state.model.params), strict=True):
    np.testing.assert_array_equal(np.asarray(after)[~live], np.asarray(before)[~live])
  adam = wild_state.opt_state[0]
  for moment in jax.tree.leaves((adam.mu, adam.nu)):
    assert not np.any(np.asarray(moment)[~live])


def _tagged_state(state):
  """A state whose Adam moments identify their parameter: mu = p + 1, nu = 2 p."""
  params = state.model.params
  adam, group = state.opt_state
  adam = adam._replace(mu=jax.tree.map(lambda p: p + 1.0, params),
                       nu=jax.tree.map(lambda p: 2.0 * p, params))
  return state._replace(opt_state=(adam, group))


def test_densification_keeps_parameters_and_optimizer_state_aligned(runs):
  run = runs["lowrank"]
  state, _ = run.step(run.state0)
  state = _tagged_state(state)
  model = state.model
  n = model.num_live
  rng = np.random.default_rng(0)
  grads = np.zeros(model.capacity, np.float32)
  grads[:n] = rng.choice([0.0, 1.0], n, p=[0.7, 0.3])  # ~30% above the threshold
  logits = np.asarray(model.params.mean["opacity_logits"]).copy()
  logits[:n][rng.random(n) < 0.2] = -10.0  # ~20% transparent: pruned
  model = model.replace(params=model.params._replace(
      mean=dict(model.params.mean, opacity_logits=jnp.asarray(logits))))
  state = state._replace(model=model, stats=state.stats._replace(
      grad_accum=jnp.asarray(grads), count=jnp.asarray((grads > 0).astype(np.int32))))
  extent = run.setup.extent
  new, report = densify_lib.densify_and_prune(
      state, rng=np.random.default_rng(1), grad_threshold=0.5,
      percent_dense=0.05, extent=extent, min_opacity=0.005,
      init_scales=run.setup.init_scales, max_gaussians=10_000)
  assert report.cloned + report.split > 0 and report.pruned > 0
  nm = new.model
  live = nm.num_live
  assert live == n - report.pruned - report.split + report.cloned + 2 * report.split
  assert nm.capacity >= live and not np.any(np.asarray(nm.mask)[live:])
  adam = new.opt_state[0]
  kept = live - report.cloned - 2 * report.split
  for g, p in nm.params.mean.items():
    p, mu, nu = (np.asarray(x) for x in (p, adam.mu.mean[g], adam.nu.mean[g]))
    np.testing.assert_allclose(mu[:kept], p[:kept] + 1.0, rtol=1e-6)  # moved together
    np.testing.assert_allclose(nu[:kept], 2.0 * p[:kept], rtol=1e-6)
    assert not np.any(mu[kept:]) and not np.any(nu[kept:])  # new rows: fresh moments
  for g, s in nm.params.b_hat.items():
    s = np.asarray(s)
    np.testing.assert_allclose(np.asarray(adam.mu.b_hat[g])[:kept], s[:kept] + 1.0, rtol=1e-6)
    fresh = s[kept:live]
    assert fresh.min() >= 0.0 and fresh.max() <= run.setup.init_scales[g]  # small, not copies
    assert set(np.unique(np.asarray(nm.signs[g])[:live])) <= {-1, 1}
    assert not np.any(s[live:]) and not np.any(np.asarray(nm.signs[g])[live:])
  # Split children are smaller than their parents by 1.6 (3DGS).
  old_scales = np.asarray(model.params.mean["log_scales"])
  children = np.asarray(nm.params.mean["log_scales"])[kept + report.cloned:live]
  assert children.max() <= old_scales[:n].max() - np.log(1.6) + 1e-5
  assert not np.any(np.asarray(new.stats.grad_accum))
  chex.assert_tree_all_finite(new)


def test_densification_respects_max_gaussians(runs):
  run = runs["lowrank"]
  state = run.state0
  n = state.model.num_live
  state = state._replace(stats=state.stats._replace(
      grad_accum=jnp.ones(state.model.capacity), count=jnp.ones(state.model.capacity,
                                                                jnp.int32)))
  new, report = densify_lib.densify_and_prune(
      state, rng=np.random.default_rng(0), grad_threshold=0.5,
      percent_dense=0.01, extent=run.setup.extent, min_opacity=0.0,
      init_scales=run.setup.init_scales, max_gaussians=n + 10)
  assert report.live <= n + 10 and report.split + report.cloned > 0


def test_opacity_reset_and_capacity_growth(runs):
  run = runs["lowrank"]
  state, _ = run.step(run.state0)
  state = _tagged_state(state)
  reset = densify_lib.reset_opacity(state)
  assert float(jnp.max(jax.nn.sigmoid(reset.model.params.mean["opacity_logits"]))) <= 0.0100001
  assert not np.any(np.asarray(reset.opt_state[0].mu.mean["opacity_logits"]))
  chex.assert_trees_all_equal(reset.opt_state[0].mu.mean["means"],
                              state.opt_state[0].mu.mean["means"])
  grown = densify_lib.grow_capacity(state, state.model.capacity + 128)
  assert grown.model.capacity == state.model.capacity + 128
  assert grown.model.num_live == state.model.num_live
  for a, b in zip(jax.tree.leaves(state.opt_state[0].mu), jax.tree.leaves(
      grown.opt_state[0].mu), strict=True):
    np.testing.assert_array_equal(np.asarray(b)[:a.shape[0]], np.asarray(a))


@pytest.mark.parametrize("kind,rank", [("lowrank", 1), ("lowrank", 64)])
@pytest.mark.slow
def test_step_finite_at_the_extremes(tiny_dataset, kind, rank):
  """One Gaussian, B_hat at its bounds, rank 1 and 64: finite loss, gradients and state."""
  config = tiny_config(kind, **{"sampler.rank": rank, "model.init_points": 1})
  run = Run(config, tiny_dataset)
  state = run.state0
  model = state.model
  spread = {g: jnp.where(model.mask.reshape((-1,) + (1,) * (v.ndim - 1)),
                         jnp.full_like(v, run.plan.spec.bound(g)), 0.0)
            for g, v in model.params.b_hat.items()}
  state = state._replace(model=model.replace(params=model.params._replace(b_hat=spread)))
  for _ in range(2):
    state, metrics = run.step(state)
    assert np.isfinite(float(metrics.loss))
  chex.assert_tree_all_finite(state)


def test_overflow_leaves_the_state_untouched(tiny_dataset):
  run = Run(resume_config(), tiny_dataset)  # a deliberately small budget
  state, metrics = run.step(run.state0)
  assert bool(metrics.overflow)
  chex.assert_trees_all_equal(state, run.state0)


def resume_config():
  """16 steps with densification at 10, checkpoints at 8, a budget that must grow."""
  return tiny_config("lowrank", **{
      "model.init_points": 200, "model.max_gaussians": 256, "train.num_steps": 16,
      "train.checkpoint_every": 8, "densify.start": 5, "densify.every": 5,
      "densify.stop": 15, "render.max_intersections": 512, "loss.volume_stop_before_end": 2,
      "loss.volume_every": 3, "train.log_every": 5})


@pytest.mark.slow
def test_resumed_run_matches_an_uninterrupted_one(tiny_dataset, tmp_path):
  config = resume_config()
  straight = train_with(config, tiny_dataset)
  assert straight.setup.step_config.settings.max_intersections > 512  # the budget grew
  assert any("densify" in e for e in straight.history)

  workdir = str(tmp_path / "run")
  killed = train_with(config, tiny_dataset, checkpoint_dir=os.path.join(workdir, "checkpoints"),
                      checkpoint_every=8, stop_at=11)
  assert int(killed.state.step) == 11  # "killed" at 11: steps 9-11 are lost, 1-8 saved
  assert [os.path.basename(p) for p in ckpt.list_checkpoints(
      os.path.join(workdir, "checkpoints"))] == ["ckpt_00000008.npz"]

  resumed = train_and_evaluate(config, workdir)  # resumes at 8, runs to 16, evaluates
  assert int(resumed.step) == 16
  for a, b in zip(jax.tree.leaves(straight.state), jax.tree.leaves(resumed), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))

  with open(os.path.join(workdir, "metrics.json")) as f:
    metrics = json.load(f)
  assert metrics["steps"] == 16 and np.isfinite(metrics["psnr"]) and 0 < metrics["ssim"] <= 1
  images = os.listdir(os.path.join(workdir, "images"))
  assert any(name.endswith("_uncertainty.png") for name in images)
  assert any(name.endswith("_render.png") for name in images)
  ply = load_ply(os.path.join(workdir, "point_cloud.ply"))
  assert len(ply["means"]) == resumed.model.num_live
  # The log survives the kill: every logged step once, in order, and the time of the
  # killed segment (steps 1-8) is counted in the total.
  with open(os.path.join(workdir, "train_log.json")) as f:
    log = json.load(f)
  assert [e["step"] for e in log] == [e["step"] for e in straight.history]
  assert all(b["seconds"] >= a["seconds"] for a, b in zip(log[:-1], log[1:], strict=True))
  assert metrics["train_seconds"] > log[0]["seconds"] > 0
  # Re-running a finished run only re-evaluates: nothing is trained twice.
  again = train_and_evaluate(config, workdir)
  assert int(again.step) == 16
  with open(os.path.join(workdir, "metrics.json")) as f:
    # (plus the moment this call spent restoring; no step was timed twice)
    assert json.load(f)["train_seconds"] == pytest.approx(metrics["train_seconds"], abs=1.0)


@pytest.mark.slow
def test_chunks_per_step_changes_speed_not_training(tiny_dataset, tmp_path):
  """`render.chunks_per_step` is a speed knob: runs agree to float rounding, a checkpoint
  resumes under another value, and result headers leave it out."""
  base = resume_config()  # a budget (512) that must grow, and a checkpoint at step 8
  wide = resume_config()
  wide.render.chunks_per_step = 64  # 2048 pairs a step: the 512 start is rounded up
  assert config_blocks.render_settings(wide.render).max_intersections == 2048
  a = train_with(base, tiny_dataset)
  directory = str(tmp_path / "checkpoints")
  train_with(base, tiny_dataset, checkpoint_dir=directory, checkpoint_every=8,
             stop_at=11)  # its checkpoint (step 8) holds a budget of 16-chunk steps
  b = train_with(wide, tiny_dataset, checkpoint_dir=directory, checkpoint_every=8)
  assert b.setup.step_config.settings.chunks_per_step == 64
  assert b.setup.step_config.settings.max_intersections % (32 * 64) == 0
  for x, y in zip(jax.tree.leaves(a.state), jax.tree.leaves(b.state), strict=True):
    np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-3, atol=1e-4)
  as_json = lambda c: json.loads(c.to_json_best_effort())
  assert as_json(base) != as_json(wide)
  assert (without_fields(as_json(base), config_blocks.SPEED_ONLY_RENDER_FIELDS)
          == without_fields(as_json(wide), config_blocks.SPEED_ONLY_RENDER_FIELDS))


@pytest.mark.slow
def test_two_samples_per_step(tiny_dataset):
  """M = 2: both samples are rendered (sequentially) and the data term is their mean."""
  run = Run(tiny_config("lowrank", **{"sampler.num_samples": 2}), tiny_dataset)
  assert run.setup.sobol.shape[1] == 2
  state, metrics = run.step(run.state0)
  assert not bool(metrics.overflow) and np.isfinite(float(metrics.loss))
  # The two Sobol points of step 0 give two different images, hence two different losses;
  # their mean is what the step reports.
  model = run.state0.model
  view = loop.view_for_step(run.setup.seed, 0, len(run.views))
  camera, image = run.views.cameras[view], run.views.images[view]
  cfg = run.setup.step_config
  per_sample = [float(losses.photometric(
      render(sample(model, jnp.asarray(z)), camera,
             background=jnp.asarray(cfg.background), settings=cfg.settings).rgb, image))
      for z in run.setup.sobol[:2]]
  assert per_sample[0] != per_sample[1]
  np.testing.assert_allclose(float(metrics.data_loss), np.mean(per_sample), rtol=1e-5)
  chex.assert_tree_all_finite(state)


def test_saved_images_flatten_path_like_view_names(tiny_dataset, tmp_path):
  """NeRF Synthetic frames are named like "./test/r_0": one flat PNG per view."""
  views = tiny_dataset.test.subset([0, 1])
  views = views.replace(names=("./test/r_0", "./test/r_1"))
  images = np.asarray(views.images)
  result = eval_lib.EvalResult({}, {}, images, np.ones(images.shape[:3], np.float32))
  eval_lib.save_images(str(tmp_path), result, views)
  written = sorted(p.name for p in tmp_path.iterdir())
  assert "test_r_0_render.png" in written and "test_r_1_uncertainty.png" in written
  assert "uncertainty.npy" in written


def test_saving_no_images_writes_nothing(tiny_dataset, tmp_path):
  """eval.save_images = 0 asks for no images: no folder, no error."""
  views = tiny_dataset.test.subset([0, 1])
  images = np.asarray(views.images)
  result = eval_lib.EvalResult({}, {}, images, np.ones(images.shape[:3], np.float32))
  eval_lib.save_images(str(tmp_path / "images"), result, views, num=0)
  assert not (tmp_path / "images").exists()


# ------------------------------------------------------------------ batches of views


def test_a_batch_takes_the_views_and_rows_of_consecutive_single_view_steps(runs):
  """Step t of a batch of B uses the views and Sobol rows of a B = 1 run's steps
  tB .. tB + B - 1; B = 1 is the B = 1 run's pick itself."""
  run, n = runs["lowrank"], 12
  one = run.setup
  index, rows = loop.step_targets(one, 5, n)
  assert index.tolist() == [loop.view_for_step(one.seed, 5, n)] and rows.shape == (1, 1, 2)
  settings = run.plan.settings.replace(batch_size=3, num_samples=2)
  setup = loop.make_setup(settings, run.state0.model, seed=one.seed, extent=one.extent,
                          num_views=n)
  assert setup.sobol.shape == (40 * 3 * 2, 2)  # steps x B x M rows of k = 2
  index, rows = loop.step_targets(setup, 5, n)
  np.testing.assert_array_equal(index, [loop.view_for_step(one.seed, p, n) for p in (15, 16, 17)])
  np.testing.assert_array_equal(rows, setup.sobol[30:36].reshape(3, 2, 2))
  assert setup.step_config.batch_size == 3 and setup.step_config.num_devices == 1
  assert one.step_config.num_devices == 1


@pytest.mark.slow
def test_batch_gradients_are_the_mean_of_the_views_and_stats_those_of_consecutive_steps(
    runs, tiny_dataset):
  """B = 2 (the definitions of `mfsample.train.step`): the data term and the gradient are the
  means of the two views' (each view's gradient taken directly, through the renderer); the
  densification statistics are those the two views add as two single-view steps at the same
  parameters (counts and radii exactly, NDC gradient norms to float rounding)."""
  run = runs["lowrank"]
  cfg = dataclasses.replace(run.setup.step_config, batch_size=2, num_devices=1)
  state = run.state0
  data = (run.views.images, run.views.cameras)
  views = [loop.view_for_step(run.setup.seed, p, len(run.views)) for p in (0, 1)]
  rows = run.setup.sobol[:2]  # M = 1: one row per position
  batch = jax.jit(functools.partial(step_lib.batch_gradients, cfg=cfg))(
      state, data, jnp.asarray(views, jnp.int32), rows.reshape(2, 1, -1))
  assert not bool(batch.overflow)

  model = state.model
  settings, background = cfg.settings, jnp.asarray(cfg.background)

  def view_loss(params, view, z):
    m = model.replace(params=params)
    out = render(sample(m, z), run.views.cameras[view], background=background,
                 settings=settings)
    return losses.photometric(out.rgb, run.views.images[view], cfg.ssim_weight)

  grad_fn = jax.jit(jax.value_and_grad(view_loss))
  per_view = [grad_fn(model.params, v, jnp.asarray(rows[i])) for i, v in enumerate(views)]
  np.testing.assert_allclose(float(batch.data_loss),
                             np.mean([float(loss) for loss, _ in per_view]), rtol=1e-6)
  assert float(batch.volume) > 0 and float(batch.loss) == float(batch.data_loss)  # step 0
  mean_grads = jax.tree.map(lambda a, b: (a + b) / 2, per_view[0][1], per_view[1][1])
  for got, want in zip(jax.tree.leaves(batch.grads), jax.tree.leaves(mean_grads), strict=True):
    got, want = np.asarray(got), np.asarray(want)
    assert np.max(np.abs(got - want)) <= 1e-4 * np.max(np.abs(want))  # float32 sums

  # Two single-view steps from the same state: what each adds to the statistics.
  singles = [run.fn(state, data, jnp.asarray([v], jnp.int32), rows[i:i + 1].reshape(1, 1, -1))
             [0].stats for i, v in enumerate(views)]
  np.testing.assert_array_equal(batch.stats.count, singles[0].count + singles[1].count)
  np.testing.assert_array_equal(batch.stats.max_radii,
                                np.maximum(singles[0].max_radii, singles[1].max_radii))
  np.testing.assert_allclose(batch.stats.grad_accum,
                             singles[0].grad_accum + singles[1].grad_accum, rtol=1e-5,
                             atol=1e-9)
  assert np.all(np.asarray(singles[0].count) <= 1) and int(np.sum(batch.stats.count)) > 0
