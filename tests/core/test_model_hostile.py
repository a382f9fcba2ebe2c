"""A broken model, z or background never gives a plausible U: an error naming it, or NaN.

The rule (docs/reliability.md, "Arguments of the public functions"): a value that is not
finite or out of its documented range raises naming the argument where it is concrete (on
the host, or on the device in a function that synchronises anyway), and makes the answer
NaN where it is traced (`jit`, `vmap`, `grad`) or left on the device. Tiny shapes shared
with tests/core/test_core_inputs.py (8 Gaussians, 8 x 8 cameras), so compilations are reused.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from planning_testlib import BOUNDS, random_model

import mfsample as mf
from mfsample import view_uncertainty as unc
from mfsample.camera import Camera
from mfsample.data import PointCloud, Views, export_colmap
from mfsample.gaussian_uncertainty import gaussian_uncertainty
from mfsample.groups import GROUPS
from mfsample.lighting import lights
from mfsample.lighting import uncertainty as lu
from mfsample.lighting.field import init_relightable
from mfsample.model import InvalidModelError, check_model, init_b_hat, model_from_mean
from mfsample.renderer import RenderSettings
from mfsample.samplers import SamplerSpec
from mfsample.train.initial import initial_model
from mfsample.train.settings import InitSettings

NAN = float("nan")
SMALL = RenderSettings(max_intersections=2048, chunk_size=8, chunks_per_step=4)
CAMERA = mf.orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5)
RELIGHTABLE = SamplerSpec(kind="lowrank", rank=2, groups=("transfer_dc",),
                          bounds=(("transfer_dc", 0.5),))


def _cams(num=2):
  return Camera.create(np.stack([np.asarray(CAMERA.world_to_camera)] * num), CAMERA.fx,
                       CAMERA.fy, CAMERA.cx, CAMERA.cy, 8, 8)


def _set(model, kind, group, rows, value):
  """`model` with `params.<kind>[group][rows]` set to `value`."""
  groups = dict(getattr(model.params, kind))
  groups[group] = groups[group].at[rows].set(value)
  return model.replace(params=model.params._replace(**{kind: groups}))


def _relightable(changes=()):
  """An untrained relightable model (m = 1, n = 4) whose samples differ, with `changes`
  ((kind, group, rows, value), ...) applied."""
  points = np.random.default_rng(0).uniform(-0.3, 0.3, (5, 3))
  model = init_relightable(jax.random.PRNGKey(0), points, spec=RELIGHTABLE, out_coeffs=1,
                           light_coeffs=4, init_scales={"transfer_dc": 0.2}, init_opacity=0.6)
  for kind, group, rows, value in changes:
    model = _set(model, kind, group, rows, value)
  return model


# name: (kind, group, rows, value, what the error says)
BROKEN = {
    "B_hat all NaN": ("b_hat", "means", slice(None), NAN,
                      r"model.params.b_hat\['means'\]\[0\] \(Gaussian 0\) is not finite "
                      r"\(8 of 8 live Gaussians\)"),
    "B_hat one inf entry": ("b_hat", "sh_dc", (3, 1, 0), np.inf,
                            r"b_hat\['sh_dc'\]\[3\] \(Gaussian 3\) is not finite"),
    "half the means NaN": ("mean", "means", slice(0, 4), NAN,
                           r"mean\['means'\]\[0\] \(Gaussian 0\) is not finite \(4 of 8"),
    "an inf log-scale": ("mean", "log_scales", (5, 2), np.inf,
                         r"mean\['log_scales'\]\[5\] \(Gaussian 5\) is not finite"),
    "a NaN colour": ("mean", "sh_dc", 6, NAN, r"mean\['sh_dc'\]\[6\]"),
    "B_hat beyond its bound": ("b_hat", "means", (2, 0, 1), 1e30,
                               r"b_hat\['means'\]\[2\] \(Gaussian 2\) reaches 1e\+30, above its "
                               r"bound 1 \(SamplerSpec.bounds"),
}


def _broken(case):
  kind, group, rows, value, _ = BROKEN[case]
  return _set(random_model("lowrank", num=8), kind, group, rows, value)


@pytest.mark.parametrize("case", BROKEN)
def test_a_broken_model_is_invalid_and_its_problems_name_the_field(case):
  model = _broken(case)
  assert not bool(model.valid)
  with pytest.raises(InvalidModelError, match=BROKEN[case][-1]):
    model.validate()
  with pytest.raises(InvalidModelError, match=BROKEN[case][-1]):
    check_model(model, sync=True)
  check_model(model)  # on the device without sync: left to the jitted part (NaN)


def test_valid_models_pass_and_dead_rows_do_not_count():
  model = random_model("lowrank", num=8)
  assert bool(model.valid) and model.problems() == []
  assert check_model(model, sync=True) is model
  dead = _set(model, "mean", "means", slice(8, None), NAN)  # padding rows, masked out
  dead = _set(dead, "b_hat", "means", slice(8, None), 1e30)
  assert bool(dead.valid) and dead.problems() == []
  b_hat = model.params.b_hat["means"]
  at_bound = _set(model, "b_hat", "means", slice(None), jnp.minimum(b_hat + 5.0, 1.0))
  assert bool(at_bound.valid)  # the bound itself is inside [0, bound]
  negative = _set(model, "b_hat", "means", 0, -3.0)  # relu(raw) = 0: harmless
  assert bool(negative.valid)
  assert bool(_relightable().valid)
  with pytest.raises(ValueError, match="model must be a mfsample.Model, got dict"):
    check_model({"params": None})


@pytest.mark.parametrize("case", ["B_hat all NaN", "half the means NaN",
                                  "B_hat beyond its bound"])
def test_functions_that_synchronise_refuse_a_broken_model_naming_the_field(case):
  """They would have returned all-equal scores (every sample culled alike: U = 0 exactly),
  a normal-looking U, or a plausible trained model."""
  model, message = _broken(case), BROKEN[case][-1]
  z = mf.sample_z(model, 2)
  views = Views(np.zeros((2, 8, 8, 3), np.float32), _cams())
  calls = [
      lambda: unc.score_cameras(model, _cams(), z, settings=SMALL),
      lambda: mf.next_views(model, _cams(), z, 1, settings=SMALL),
      lambda: mf.optimize_view(model, CAMERA, z, steps=1, settings=SMALL),
      lambda: mf.fit(model, views, mf.TrainSettings(num_steps=1), key=jax.random.PRNGKey(0)),
      lambda: mf.fit_b_hat(model, views, mf.TrainSettings(num_steps=1),
                           key=jax.random.PRNGKey(0)),
      lambda: gaussian_uncertainty(model, CAMERA, z, settings=SMALL),
  ]
  for call in calls:
    with pytest.raises(InvalidModelError, match=message):
      call()


def test_light_functions_that_synchronise_refuse_a_broken_relightable_model():
  model = _relightable([("mean", "transfer_dc", 2, NAN)])
  z = mf.sample_z(model, 2)
  message = r"model.params.mean\['transfer_dc'\]\[2\] \(Gaussian 2\) is not finite"
  light = lights.uniform_light(4)
  for call in (lambda: lu.light_gram(model, _cams(), z, settings=SMALL),
               lambda: mf.next_lights(model, _cams(), z, np.stack([light, -light]), 1,
                                      settings=SMALL),
               lambda: mf.optimize_light(model, _cams(), z, light, steps=1, settings=SMALL),
               lambda: lu.light_uncertainty_fitted(model, _cams(), z, light, settings=SMALL)):
    with pytest.raises(InvalidModelError, match=message):
      call()


@pytest.mark.slow
@pytest.mark.parametrize("case", ["B_hat all NaN", "half the means NaN", "an inf log-scale",
                                  "B_hat beyond its bound"])
def test_traced_or_unsynchronised_a_broken_model_gives_nan_never_a_finite_u(case):
  """`uncertainty` does not synchronise: a model on the device gives NaN (before: U = 0
  exactly for B_hat all NaN, a normal-looking U for half the means NaN); under jit the same,
  and the valid model's U stays finite and positive."""
  good, bad = random_model("lowrank", num=8), _broken(case)
  z = mf.sample_z(good, 2)
  u = unc.uncertainty(bad, CAMERA, z, settings=SMALL)
  assert np.isnan(float(u.value)) and np.all(np.isnan(u.pixel_map))
  jitted = jax.jit(lambda m: unc.uncertainty(m, CAMERA, z, settings=SMALL).value)
  assert float(jitted(good)) > 0 and np.isnan(float(jitted(bad)))
  scores = jax.jit(lambda m: unc._score(m, _cams(), z, jnp.zeros(3), settings=SMALL,
                                        chunk_size=1, num_devices=1, with_maps=False).values)
  assert np.all(np.isnan(scores(bad))) and np.all(scores(good) > 0)


@pytest.mark.slow
def test_under_vmap_and_grad_a_broken_model_gives_nan():
  good, bad = random_model("lowrank", num=8), _broken("half the means NaN")
  z = mf.sample_z(good, 2)
  batch = jax.tree.map(lambda a, b: jnp.stack([a, b]), good, bad)
  values = jax.vmap(lambda m: unc.uncertainty(m, CAMERA, z, settings=SMALL).value)(batch)
  assert float(values[0]) > 0 and np.isnan(float(values[1]))
  value, _ = jax.value_and_grad(lambda c: unc.uncertainty(bad, c, z, settings=SMALL).value)(
      CAMERA)
  assert np.isnan(float(value))


@pytest.mark.slow
def test_light_uncertainty_of_a_broken_relightable_model_is_nan():
  good, bad = _relightable(), _relightable([("b_hat", "transfer_dc", slice(None), NAN)])
  z, xi = mf.sample_z(good, 2), lights.uniform_light(4)
  assert float(lu.light_uncertainty(good, _cams(), z, xi, settings=SMALL).value) > 0
  assert np.isnan(float(lu.light_uncertainty(bad, _cams(), z, xi, settings=SMALL).value))
  image, _, _ = lu.light_pixel_map(bad, CAMERA, z, jnp.asarray(xi, jnp.float32),
                                   settings=SMALL)
  assert np.all(np.isnan(image))


# ---------------------------------------------------------------------- construction


@pytest.mark.parametrize("scale, message", [
    (1e39, r"points\[0\] = .* is out of range: magnitudes must be at most 1e\+18"),
    (1e20, r"points\[0\] = .* is out of range"),
    (np.inf, r"points\[0\] is not finite"),
])
def test_initial_points_beyond_float32_or_the_world_limit_are_refused(scale, message):
  """1e39 is finite in float64 and inf once the model is float32 (before: inf centres and
  a numpy warning)."""
  points = np.random.default_rng(0).uniform(-1, 1, (5, 3))
  points[0] *= scale
  spec = SamplerSpec(kind="lowrank", groups=("means",), bounds=(("means", 1.0),))
  with pytest.raises(ValueError, match=message):
    mf.init_model(jax.random.PRNGKey(0), points, spec=spec, sh_degree=0,
                  init_scales={"means": 1e-3})
  with pytest.raises(ValueError, match=message):
    init_relightable(jax.random.PRNGKey(0), points, spec=RELIGHTABLE, out_coeffs=1,
                     light_coeffs=4, init_scales={"transfer_dc": 0.1})


@pytest.mark.parametrize("group, value, message", [
    ("means", 1e39, r"mean\['means'\]\[1\] = .* is out of range"),
    ("means", 1e20, r"mean\['means'\]\[1\] = .* is out of range"),
    ("log_scales", 1e39, r"mean\['log_scales'\]\[1\] = .* is out of range: .* the model is "
                         "float32"),
    ("opacity_logits", -np.inf, r"mean\['opacity_logits'\]\[1\] is not finite"),
])
def test_model_from_mean_refuses_values_float32_cannot_hold(group, value, message):
  mean = {"means": np.zeros((3, 3)), "log_scales": np.full((3, 3), -2.0),
          "quats": np.tile([1.0, 0, 0, 0], (3, 1)), "opacity_logits": np.zeros(3),
          "sh_dc": np.zeros((3, 3))}
  mean[group] = np.array(mean[group], np.float64)
  mean[group][1] = value
  spec = SamplerSpec(kind="lowrank", groups=("means",), bounds=(("means", 1.0),))
  with pytest.raises(ValueError, match=message):
    model_from_mean(jax.random.PRNGKey(0), mean, spec=spec, init_scales={"means": 1e-3})


def test_init_scales_above_the_bounds_give_entries_at_the_bounds():
  """The bounds apply from the first step on; they apply at initialisation too (before: an
  init scale of 1e30 gave U = inf until the first step clamped it)."""
  spec = SamplerSpec(kind="lowrank", rank=2, groups=GROUPS, bounds=BOUNDS)
  points = np.random.default_rng(0).uniform(-0.5, 0.5, (8, 3))
  model = mf.init_model(jax.random.PRNGKey(0), points, spec=spec, sh_degree=0,
                        init_scales=dict.fromkeys(GROUPS, 1e30))
  assert bool(model.valid)
  for g, bound in BOUNDS:
    if g in model.params.b_hat:
      assert float(jnp.max(model.params.b_hat[g])) == np.float32(bound)
  u = unc.uncertainty(model, CAMERA, mf.sample_z(model, 2), settings=SMALL)
  assert np.isfinite(float(u.value))
  relit = init_relightable(jax.random.PRNGKey(0), points, spec=RELIGHTABLE, out_coeffs=1,
                           light_coeffs=4, init_scales={"transfer_dc": 1e30})
  assert float(jnp.max(relit.params.b_hat["transfer_dc"])) == np.float32(0.5)


def test_init_scales_within_the_bounds_draw_exactly_as_before():
  """The clamp changes no entry of a valid draw: raw = scale * U[0, 1], bit for bit."""
  spec = SamplerSpec(kind="block", rank=3, groups=("means", "sh_dc"),
                     bounds=(("means", 0.01), ("sh_dc", 0.5)))
  shapes = {"means": (3,), "sh_dc": (3,), "quats": (4,)}
  b_hat, _ = init_b_hat(np.random.default_rng(7), 50, shapes, spec,
                        {"means": 0.01, "sh_dc": 0.3})
  rng = np.random.default_rng(7)
  for g, scale in (("means", 0.01), ("sh_dc", 0.3)):
    expected = (scale * rng.random((50, 3, 3))).astype(np.float32)
    rng.random((50, 3, 3))  # the signs
    np.testing.assert_array_equal(b_hat[g], expected)


# ---------------------------------------------------------------------- z


@pytest.mark.parametrize("z, message", [
    (np.array([[0.5, -0.5], [1.5, 0.1]], np.float32), r"z\[1\] \(sample 1\) is outside "
                                                     r"\[-1, 1\] \(max \|z\| = 1.5; 1 of 2"),
    (np.array([[-3.0, 0.0], [0.2, 0.1]]), r"z\[0\] \(sample 0\) is outside \[-1, 1\]"),
    (np.array([[np.inf, 0.0], [0.2, 0.1]]), r"z\[0\] \(sample 0\) is not finite"),
])
def test_z_outside_its_range_is_refused_naming_the_sample(z, message):
  """z ~ U[-1, 1]^k for every sampler kind; a z of 3 multiplied U by 9 (before: accepted)."""
  model, relit = random_model("lowrank", num=8), _relightable()
  light = lights.uniform_light(4)
  for call in (lambda: unc.uncertainty(model, CAMERA, z, settings=SMALL),
               lambda: unc.score_cameras(model, _cams(), z, settings=SMALL),
               lambda: unc.score_cameras(model, _cams(), jnp.asarray(z), settings=SMALL),
               lambda: mf.next_views(model, _cams(), jnp.asarray(z), 1, settings=SMALL),
               lambda: mf.optimize_view(model, CAMERA, jnp.asarray(z), steps=1,
                                        settings=SMALL),
               lambda: lu.light_uncertainty(relit, _cams(), z, light, settings=SMALL),
               lambda: lu.light_gram(relit, _cams(), jnp.asarray(z), settings=SMALL)):
    with pytest.raises(ValueError, match=message):
      call()


@pytest.mark.parametrize("kind", ["diagonal", "block"])
def test_z_range_holds_for_every_sampler_kind(kind):
  model = random_model(kind, num=8)
  z = np.array(mf.sample_z(model, 2))
  assert np.all(np.abs(z) <= 1.0)
  unc.check_z(model, z)  # what sample_z draws is in range
  z[1].flat[5] = 1.01
  with pytest.raises(ValueError, match=r"z\[1\] \(sample 1\) is outside \[-1, 1\]"):
    unc.check_z(model, z)


@pytest.mark.slow
def test_z_at_the_ends_of_its_range_is_accepted_and_a_traced_one_outside_gives_nan():
  model = random_model("lowrank", num=8)
  ends = np.array([[1.0, -1.0], [-1.0, 1.0]], np.float32)
  assert float(unc.uncertainty(model, CAMERA, ends, settings=SMALL).value) > 0
  u = jax.jit(lambda z: unc.uncertainty(model, CAMERA, z, settings=SMALL))
  assert float(u(ends).value) > 0
  assert np.isnan(float(u(ends * 3.0).value)) and np.all(np.isnan(u(ends * 3.0).pixel_map))
  on_device = jnp.asarray(ends * 3.0)  # not fetched by uncertainty (no sync): NaN
  assert np.isnan(float(unc.uncertainty(model, CAMERA, on_device, settings=SMALL).value))


def test_optimize_settings_keep_a_scaled_z_in_range():
  from mfsample.planning.optimize import OptimizeSettings

  with pytest.raises(ValueError, match="OptimizeSettings.z_drop_scale must be a finite number "
                                       r"in \[0.0, 1.0\], got 2.0"):
    OptimizeSettings(z_drop_scale=2.0)


# ---------------------------------------------------------------------- backgrounds


@pytest.mark.parametrize("background", [np.array([255, 255, 255], np.uint8),
                                        np.array([1, 1, 1]), jnp.array([0, 0, 1], jnp.int32),
                                        np.array([True, True, False])])
def test_integer_backgrounds_are_refused_eagerly_and_under_jit(background):
  """A uint8 white gave pixels up to 255. Dtypes are static: refused under jit too."""
  gaussians = mf.mean_gaussians(random_model("lowrank", num=8))
  message = "background must hold floats"
  with pytest.raises(ValueError, match=message):
    mf.render(gaussians, CAMERA, background=background, settings=SMALL)
  with pytest.raises(ValueError, match=message):
    jax.jit(lambda b: mf.render(gaussians, CAMERA, background=b, settings=SMALL))(background)
  model = random_model("lowrank", num=8)
  with pytest.raises(ValueError, match=message):
    unc.uncertainty(model, CAMERA, mf.sample_z(model, 2), background=background)
  with pytest.raises(ValueError, match=message):
    unc.score_cameras(model, _cams(), mf.sample_z(model, 2), background=background,
                      settings=SMALL)


@pytest.mark.slow
def test_python_numbers_are_float_colours_and_colours_outside_0_1_give_nan():
  gaussians = mf.mean_gaussians(random_model("lowrank", num=8))
  white = mf.render(gaussians, CAMERA, background=(1.0, 1.0, 1.0), settings=SMALL).rgb
  np.testing.assert_array_equal(
      mf.render(gaussians, CAMERA, background=(1, 1, 1), settings=SMALL).rgb, white)
  assert np.all(np.isfinite(white)) and float(jnp.max(white)) <= 1.0 + 1e-6
  for bad in ((255, 255, 255), (0.0, -0.5, 0.0), (NAN, 0.0, 0.0)):
    out = mf.render(gaussians, CAMERA, background=bad, settings=SMALL)
    assert np.all(np.isnan(out.rgb)), bad
    assert np.all(np.isfinite(out.alpha))  # the opacity does not depend on the background
  # Features are any values: a background of 5 is blended as given.
  feats = mf.render(gaussians, CAMERA, background=jnp.full((1,), 5.0), settings=SMALL,
                    features=jnp.ones((gaussians.means.shape[0], 1)))
  assert np.all(np.isfinite(feats.rgb)) and float(jnp.max(feats.rgb)) > 1.0


@pytest.mark.slow
def test_a_background_outside_0_1_is_named_or_gives_nan_in_u():
  model = random_model("lowrank", num=8)
  z = mf.sample_z(model, 2)
  with pytest.raises(ValueError, match=r"background\[1\] = 2 is outside \[0, 1\]"):
    unc.uncertainty(model, CAMERA, z, background=np.array([0.0, 2.0, 0.0]))
  with pytest.raises(ValueError, match=r"background\[0\] = 255 is outside \[0, 1\]"):
    unc.score_cameras(model, _cams(), z, background=jnp.full((3,), 255.0), settings=SMALL)
  u = jax.jit(lambda b: unc.uncertainty(model, CAMERA, z, background=b, settings=SMALL).value)
  assert np.isfinite(float(u(jnp.ones(3)))) and np.isnan(float(u(jnp.full((3,), 255.0))))


# ---------------------------------------------------------------------- point-cloud colours


@pytest.mark.parametrize("rgb, message", [
    (np.full((4, 3), 200.0, np.float32), r"points.rgb\[0\] = \[200.0, 200.0, 200.0\] is outside "
                                         r"\[0, 1\] \(4 of 4 points"),
    (np.full((4, 3), 40000, np.uint16), "points.rgb must hold floats in \\[0, 1\\] .* got dtype "
                                        "uint16"),
    (np.full((4, 3), 200, np.uint8), "points.rgb must hold floats .* got dtype uint8"),
    (np.array([[0.5, 0.5, 0.5]] * 3 + [[0.5, NAN, 0.5]]), r"points.rgb\[3\] .* outside"),
])
def test_point_cloud_colours_on_another_scale_are_refused_never_clipped_to_white(tmp_path, rgb,
                                                                                  message):
  points = PointCloud(np.random.default_rng(0).uniform(-1, 1, (4, 3)).astype(np.float32), rgb)
  with pytest.raises(ValueError, match=message):
    points.validate()
  init = InitSettings(init_from="points", sh_degree=0)
  spec = SamplerSpec(kind="lowrank", groups=("means",), bounds=(("means", 1.0),))
  with pytest.raises(ValueError, match=message):
    initial_model(init, spec, {"means": 1e-3}, seed=0, bounds=(-1.0, 1.0), points=points)
  views = Views(np.zeros((2, 8, 8, 3), np.float32), _cams())
  pytest.importorskip("pycolmap")
  with pytest.raises(ValueError, match=message):
    export_colmap(tmp_path, views, points)
  assert not (tmp_path / "images").exists()  # refused before anything is written


def test_valid_point_cloud_colours_initialise_the_model_as_given():
  rgb = np.array([[0.0, 0.5, 1.0], [0.2, 0.4, 0.6], [1.0, 1.0, 1.0]], np.float32)
  points = PointCloud(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), rgb)
  spec = SamplerSpec(kind="lowrank", groups=("means",), bounds=(("means", 1.0),))
  model = initial_model(InitSettings(init_from="points", sh_degree=0), spec, {"means": 1e-3},
                        seed=0, bounds=(-1.0, 1.0), points=points)
  colour = 0.5 + 0.28209479177387814 * np.asarray(model.params.mean["sh_dc"][:3], np.float64)
  np.testing.assert_allclose(colour, rgb, atol=1e-6)
