"""Hostile inputs to the top-level modules: cameras, model, samplers, U, metrics, top_k, writes.

For each entry point, a table of bad inputs and what they give: each row is a bad input and
its expected outcome, a clear error whose message names the field or the file, or a defined
behaviour (docs/reliability.md lists the same tables).
"""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hostile_testlib import BAD_POSES, NAN, POINTS, SMALL, W2C, _cams, _relightable
from PIL import Image
from planning_testlib import random_model

from mfsample import _json, metrics, orbit_camera, samplers
from mfsample import view_uncertainty as unc
from mfsample.camera import Camera, InvalidCameraError
from mfsample.groups import GROUPS
from mfsample.lighting import field as light_field
from mfsample.lighting import lights
from mfsample.lighting import uncertainty as lu
from mfsample.model import init_model, model_from_mean, sample
from mfsample.samplers import SamplerSpec, sample_z
from mfsample.selection import top_k

# ====================================================================== Camera constructors


@pytest.mark.parametrize("name", BAD_POSES)
def test_camera_create_refuses(name):
  w2c, fx, fy, cx, cy, message = BAD_POSES[name]
  with pytest.raises(InvalidCameraError, match=message):
    Camera.create(w2c, fx, fy, cx, cy, 16, 16)


def test_camera_errors_name_the_batch_index():
  w2c = np.stack([W2C, W2C, np.diag([1.0, -1.0, 1.0, 1.0]) @ W2C])
  with pytest.raises(InvalidCameraError, match=r"world_to_camera\[2\] is a reflection.*fx\[1\]"):
    Camera.create(w2c, np.array([8.0, -1.0, 8.0]), 8.0, 8.0, 8.0, 16, 16)


@pytest.mark.parametrize("call, error, message", [
    (lambda: Camera.create(np.eye(3), 1, 1, 0, 0, 4, 4), ValueError, r"\[\.\.\., 4, 4\]"),
    (lambda: Camera.create(np.stack([W2C] * 2), np.ones(3), 1, 0, 0, 4, 4), ValueError,
     "fx of shape"),
    (lambda: Camera.create(W2C, 1, 1, 0, 0, 0, 4), ValueError, "width must be an integer"),
    (lambda: Camera.create(W2C, 1, 1, 0, 0, 4, 2.5), ValueError, "height must be an integer"),
    (lambda: Camera.create(W2C, 1, 1, 0, 0, True, 4), ValueError, "width must be an integer"),
    (lambda: Camera.look_at(np.array([NAN, 0, 1]), np.zeros(3), np.array([0, 0, 1.0]), 0.8,
                            8, 8), InvalidCameraError, "non-finite"),
    (lambda: Camera.look_at(np.array([3.0, 0, 1]), np.zeros(3), np.array([0, 0, 1.0]), 60.0,
                            8, 8), ValueError, r"fov_x = 60.0 must be in \(0, pi\) radians"),
    (lambda: Camera.look_at(np.array([3.0, 0, 1]), np.zeros(3), np.array([0, 0, 1.0]), 0.0,
                            8, 8), ValueError, r"fov_x = 0.0 must be in \(0, pi\)"),
    (lambda: Camera.from_blender(np.diag([2.0, 2, 2, 1]), 0.8, 8, 8), InvalidCameraError,
     "not rigid"),
    (lambda: Camera.from_blender(np.eye(4), "wide", 8, 8), ValueError,
     "camera_angle_x = 'wide' must be a number"),
    (lambda: Camera.look_at(np.zeros((2, 3)) + 3, np.zeros((3, 3)), np.array([0, 0, 1.0]), 0.8,
                            8, 8), ValueError, r"batch shapes of eye \[2, 3\], target \[3, 3\]"),
    (lambda: Camera.look_at(np.array([3.0, 0]), np.zeros(3), np.array([0, 0, 1.0]), 0.8, 8, 8),
     ValueError, r"eye must have shape \[\.\.\., 3\], got \[2\]"),
    (lambda: Camera.look_at(np.array([3.0, 0, 1]), np.zeros(3), np.array([0, NAN, 1.0]), 0.8,
                            8, 8), InvalidCameraError, r"up = \[0.0, nan, 1.0\] is not finite"),
    (lambda: Camera.look_at(np.array([3.0, 0, 1]), np.zeros(3), np.zeros(3), 0.8, 8, 8),
     InvalidCameraError, "up is a zero vector"),
    (lambda: Camera.from_blender(np.eye(4)[:, :3], 0.8, 8, 8), ValueError,
     r"c2w must have shape \[\.\.\., 4, 4\] or \[\.\.\., 3, 4\], got \[4, 3\]"),
])
def test_camera_constructor_table(call, error, message):
  with pytest.raises(error, match=message):
    call()


@pytest.mark.parametrize("eye, target", [
    ((0.0, 0.0, 3.0), (0.0, 0.0, 0.0)),  # looking along up: a fallback up vector
    ((1.0, 1.0, 1.0), (1.0, 1.0, 1.0)),  # eye == target: a fallback direction
])
def test_degenerate_look_at_is_a_valid_camera(eye, target):
  cam = Camera.look_at(np.array(eye), np.array(target), np.array([0.0, 0.0, 1.0]), 0.8, 8, 8)
  assert bool(cam.valid) and cam.problems() == []


def test_cameras_are_checkable_not_raising_under_jit_and_vmap():
  """Traced constructors check nothing (no error, no sync); `valid` flags the bad ones.
  (Under grad, tests/core/test_camera.py differentiates through look_at.)"""
  up = jnp.array([0.0, 0.0, 1.0])
  cams = Camera(jnp.stack([jnp.asarray(W2C, jnp.float32)] * 3),
                jnp.array([8.0, 0.0, 8.0]), jnp.full(3, 8.0), jnp.full(3, 8.0),
                jnp.full(3, 8.0), 16, 16)  # the raw constructor checks shapes only

  @jax.jit
  def flags_of(eyes, cameras):
    looked = jax.vmap(lambda e: Camera.look_at(e, jnp.zeros(3), up, 0.8, 8, 8).valid)(eyes)
    return looked, jax.vmap(lambda c: c.valid)(cameras)

  looked, given = flags_of(jnp.array([[3.0, 0.0, 1.0], [NAN, 0.0, 1.0]]), cams)
  np.testing.assert_array_equal(looked, [True, False])
  np.testing.assert_array_equal(given, [True, False, True])


# ====================================================================== init_model

SPEC = SamplerSpec(kind="lowrank", rank=2, groups=GROUPS, bounds=tuple((g, 1.0) for g in GROUPS))
SCALES = {g: 1e-3 for g in GROUPS}


@pytest.mark.parametrize("changes, message", [
    ({"points": POINTS[:, :2]}, r"points must have shape \[N >= 1, 3\]"),
    ({"points": np.zeros((0, 3))}, r"points must have shape \[N >= 1, 3\]"),
    ({"points": np.where(np.arange(5)[:, None] == 3, NAN, POINTS)}, r"points\[3\] is not finite"),
    ({"capacity": 3}, "capacity 3 < number of points 5"),
    ({"sh_degree": 4}, "sh_degree must be an integer in 0..3"),
    ({"init_opacity": 1.0}, r"init_opacity must be a finite number in \(0.0, 1.0\), got 1.0"),
    ({"init_opacity": 0.0}, r"init_opacity must be a finite number in \(0.0, 1.0\), got 0.0"),
    ({"colors": np.ones((4, 3))}, r"colors must have shape \[N=5, 3\]"),
    ({"colors": np.full((5, 3), np.inf)}, r"colors\[0\] is not finite"),
    ({"init_scales": {"means": 1e-3}}, r"init_scales\['log_scales'\] must be a finite number"),
    ({"init_scales": {**SCALES, "quats": -1.0}}, r"init_scales\['quats'\]"),
    ({"colors": np.full((5, 3), 128, np.uint8)}, r"colors must be floats in \[0, 1\], got "
                                                 r"dtype uint8 \(for 8-bit colours pass "
                                                 r"colors / 255\)"),
    ({"colors": np.full((5, 3), 1.5)}, r"colors\[0\] = \[1.5, 1.5, 1.5\] is outside \[0, 1\]"),
    ({"points": np.full((5, 3), "1")}, "points must hold real numbers"),
    ({"capacity": 7.5}, "capacity must be an integer >= 1, got 7.5"),
    ({"init_opacity": NAN}, r"init_opacity must be a finite number in \(0.0, 1.0\), got nan"),
    ({"key": 0}, r"key must be one JAX PRNG key .*, got 0"),
    ({"key": jnp.zeros(3, jnp.uint32)}, r"key must be one JAX PRNG key .*shape \[3\]"),
])
def test_init_model_table(changes, message):
  kwargs = {"key": jax.random.PRNGKey(0), "points": POINTS, "spec": SPEC, "sh_degree": 1,
            "init_scales": SCALES, **changes}
  with pytest.raises(ValueError, match=message):
    init_model(**kwargs)


def test_model_from_a_mean_with_a_non_finite_row_is_refused():
  mean = {"means": POINTS.astype(np.float32), "log_scales": np.zeros((5, 3), np.float32),
          "quats": np.tile(np.float32([1, 0, 0, 0]), (5, 1)), "opacity_logits": np.zeros(5),
          "sh_dc": np.zeros((5, 3), np.float32)}
  mean["log_scales"][4, 1] = np.inf
  with pytest.raises(ValueError, match=r"mean\['log_scales'\]\[4\] is not finite"):
    model_from_mean(jax.random.PRNGKey(0), mean, spec=SPEC, init_scales=SCALES)


@pytest.mark.parametrize("kwargs, message", [
    ({"kind": "gaussian"}, "SamplerSpec.kind must be one of"),
    ({"kind": "lowrank", "rank": 0}, "rank must be an integer >= 1"),
    ({"groups": ("means", "colour")}, r"SamplerSpec.groups must be .* \('colour' is not one\)"),
    ({"groups": ("means",), "bounds": ()}, "no bound given for"),
    # A bound of NaN, -1 or 0 would clamp B_hat to NaN or 0 after the first training step.
    ({"groups": ("means",), "bounds": (("means", NAN),)},
     r"SamplerSpec.bounds\['means'\] must be a finite number > 0.0, got nan"),
    ({"groups": ("means",), "bounds": (("means", -1.0),)}, r"bounds\['means'\] .*got -1.0"),
    ({"groups": ("means",), "bounds": (("means", 0),)}, r"bounds\['means'\] .*got 0"),
    ({"groups": ("means",), "bounds": (("means", True),)}, r"bounds\['means'\] .*got True"),
    ({"rank": 2.5}, "SamplerSpec.rank must be an integer >= 1, got 2.5"),
    ({"kind": "diagonal", "rank": 0}, "SamplerSpec.rank must be an integer >= 1"),
    ({"groups": ("means", "means"), "bounds": (("means", 1.0),)}, "'means' repeats"),
    ({"groups": ("means",), "bounds": (("means", 1.0), ("means", 2.0))}, "two for 'means'"),
    ({"groups": ("means",), "bounds": (("colour", 1.0),)}, "names an unknown group 'colour'"),
    ({"groups": ["means"], "bounds": (("means", 1.0),)}, "SamplerSpec.groups must be a tuple"),
    ({"groups": ("means",), "bounds": {"means": 1.0}}, "SamplerSpec.bounds must be a tuple"),
])
def test_sampler_spec_table(kwargs, message):
  with pytest.raises(ValueError, match=message):
    SamplerSpec(**kwargs)


# ====================================================================== samplers, uncertainty


@pytest.mark.parametrize("call, message", [
    (lambda m: samplers.sobol_z(-1, 2, 0), "num must be an integer >= 0"),
    (lambda m: samplers.sobol_z(4, 2.5, 0), "dim must be an integer"),
    (lambda m: samplers.sobol_z(4, 30_000, 0), "exceeds the 21201 dimensions"),
    (lambda m: samplers.sobol_z(4, 2, 0, offset=-3), "offset must be an integer >= 0"),
    (lambda m: sample(m, jnp.zeros(3)), r"z must have shape \(2,\)"),
    (lambda m: sample_z(m, 0), "num_samples must be an integer >= 1"),
    (lambda m: unc.score_cameras(m, orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5),
                                 jnp.zeros((2, 2)), settings=SMALL),
     "batched over one axis"),
    (lambda m: samplers.sobol_z(4, 2, -1), "sobol_z: seed must be an integer in"),
    (lambda m: samplers.draw_z(m, 2, None, np.zeros((3, 2))),
     r"rows must have shape \[2, 2\] \(Sobol rows of the step\)"),
    (lambda m: sample_z(m, 2, seed=-1), r"seed must be an integer in \[0, "),
    (lambda m: sample_z(m, 2, seed=0.5), "seed must be an integer"),
    (lambda m: unc.pixel_variance(jnp.zeros((0, 4, 4, 3))), r"rgbs must have shape \[M >= 1, "),
    (lambda m: unc.score_cameras(m, _cams(), jnp.zeros((2, 2)), settings=SMALL, chunk_size=0),
     "chunk_size must be an integer >= 1, got 0"),
    (lambda m: unc.score_cameras(m, _cams(), jnp.zeros((2, 2)), settings=SMALL,
                                 num_devices=64), r"num_devices must be an integer in \[1, "),
    (lambda m: unc.score_cameras(m, _cams(), jnp.zeros((2, 2)), settings=SMALL, max_budget=0),
     "max_budget must be an integer >= 1"),
    (lambda m: unc.score_cameras(m, _cams(), jnp.zeros((2, 2)), settings=SMALL,
                                 background=(1.0, 1.0)), r"background must have shape \[3\]"),
    (lambda m: unc.uncertainty(m, orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5),
                               jnp.zeros((2, 2)),
                               background=np.array([0.0, NAN, 0.0])),
     r"background\[1\] is not finite"),
    (lambda m: unc.uncertainty(m, orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5),
                               jnp.zeros((2, 2)), num_devices=0),
     r"num_devices must be an integer in \[1, "),
])
def test_sampler_and_uncertainty_table(call, message):
  with pytest.raises(ValueError, match=message):
    call(random_model("lowrank", num=8))


Z_BAD = {  # z of M = 2 low-rank samples (k = 2) with one bad row, and z with no sample
    "nan row": (np.array([[0.5, -0.5], [NAN, 0.1]], np.float32),
                r"z\[1\] \(sample 1\) is not finite \(1 of 2 samples"),
    "inf entry": (np.array([[0.5, np.inf], [0.3, 0.1]]), r"z\[0\] \(sample 0\) is not finite"),
    "no sample": (np.zeros((0, 2), np.float32), r"z must have shape \[M >= 1, 2\] .*got \[0, 2\]"),
    "wrong k": (np.zeros((2, 3), np.float32), r"z must have shape \[M >= 1, 2\] .*got \[2, 3\]"),
}


@pytest.mark.parametrize("case", Z_BAD)
@pytest.mark.parametrize("entry", ["uncertainty", "score_cameras", "light_uncertainty",
                                   "light_gram"])
def test_z_without_samples_or_with_a_non_finite_one_is_refused(case, entry):
  """A NaN row of z makes every Gaussian of its sample non-finite; the renderer culls them and
  U would come out finite and wrong. M = 0 would be a mean over nothing (NaN)."""
  z, message = Z_BAD[case]
  calls = {
      "uncertainty": lambda: unc.uncertainty(
          random_model("lowrank", num=8),
          orbit_camera(0.3, 0.4, width=8, height=8, distance=3.5), z, settings=SMALL),
      "score_cameras": lambda: unc.score_cameras(random_model("lowrank", num=8), _cams(), z,
                                                 settings=SMALL),
      "light_uncertainty": lambda: lu.light_uncertainty(_relightable(), _cams(), z,
                                                        lights.uniform_light(4), settings=SMALL),
      "light_gram": lambda: lu.light_gram(_relightable(), _cams(), z, settings=SMALL),
  }
  with pytest.raises(ValueError, match=message):
    calls[entry]()


def test_under_jit_a_non_finite_z_or_light_gives_nan_never_a_finite_u():
  """Traced values cannot raise: U, its map and U(xi) are NaN (before: finite for a NaN row of
  z, exactly 0 for a NaN light), and a finite input still gives a finite U > 0. A z on the
  device is not fetched to be checked by `uncertainty` (no sync per call): it gives NaN too;
  `score_cameras` synchronises anyway, so it checks it."""
  model, relit, camera = random_model("lowrank", num=8), _relightable(), _cams(1)
  u = jax.jit(lambda z: unc.uncertainty(model, camera[0], z, settings=SMALL))
  good = np.array([[0.5, -0.5], [-0.4, 0.3]], np.float32)
  assert float(u(good).value) > 0
  bad = u(good * np.array([[1.0], [NAN]], np.float32))
  assert np.isnan(float(bad.value)) and np.all(np.isnan(bad.pixel_map))
  on_device = jnp.asarray(good * np.array([[1.0], [NAN]], np.float32))
  assert np.isnan(float(unc.uncertainty(model, camera[0], on_device, settings=SMALL).value))
  with pytest.raises(ValueError, match=r"z\[1\] \(sample 1\) is not finite"):
    unc.score_cameras(model, _cams(), on_device, settings=SMALL, num_devices=1)
  xi = lights.uniform_light(4)
  u_light = jax.jit(lambda x: lu.light_uncertainty(relit, camera, good, x, settings=SMALL).value)
  assert float(u_light(jnp.asarray(xi, jnp.float32))) > 0
  assert np.isnan(float(u_light(jnp.asarray(xi * NAN, jnp.float32))))
  relit_image = jax.jit(lambda x: light_field.render_relit(
      relit.params.mean, relit.mask, x, camera[0], settings=SMALL).rgb)
  assert np.all(np.isnan(relit_image(jnp.full(4, NAN))))
  with pytest.raises(ValueError, match=r"xi has non-finite coefficients at \[0, 1, 2, 3\]"):
    light_field.render_relit(relit.params.mean, relit.mask, np.full(4, NAN), camera[0],
                             settings=SMALL)


def test_scores_of_invalid_cameras_are_nan_and_leave_the_others_alone():
  """One invalid candidate camera gives U = NaN for itself only (never a silent 0)."""
  model = random_model("lowrank", num=16)
  good = np.asarray(orbit_camera(0.3, 0.4, width=8, height=8, distance=3.0).world_to_camera,
                    np.float32)
  cams = Camera(jnp.asarray(np.stack([good, np.diag([1.0, 1, -1, 1]).astype(np.float32) @ good,
                                      good])),
                jnp.full(3, 6.0), jnp.full(3, 6.0), jnp.full(3, 4.0), jnp.full(3, 4.0), 8, 8)
  z = sample_z(model, 2)
  scores, _ = unc.score_cameras(model, cams, z, settings=SMALL, num_devices=1)
  values = np.asarray(scores.values)
  assert np.isnan(values[1]) and np.all(np.isfinite(values[[0, 2]]))
  assert values[0] == values[2] and values[0] > 0


def test_one_sample_is_allowed_and_gives_zero_uncertainty():
  z = sample_z(random_model("lowrank", num=16), 1)
  assert z.shape == (1, 2)
  rgbs = jnp.asarray(np.random.default_rng(0).uniform(size=(1, 4, 5, 3)), jnp.float32)
  assert not np.any(np.asarray(unc.pixel_variance(rgbs)))  # Eq. 10 with M = 1: exactly 0


# ====================================================================== metrics, selection

IMAGE = np.random.default_rng(0).uniform(size=(12, 12, 3)).astype(np.float32)


@pytest.mark.parametrize("call, message", [
    (lambda: metrics.psnr(IMAGE, IMAGE[..., :1]),
     r"psnr: images a and b must have the same shape, got \[12, 12, 3\] and \[12, 12, 1\]"),
    (lambda: metrics.mse(IMAGE[None], IMAGE), "mse: images a and b must have the same shape"),
    (lambda: metrics.ssim(IMAGE, IMAGE[:11]), "ssim: images a and b must have the same shape"),
    (lambda: metrics.psnr(IMAGE, (IMAGE * 255).astype(np.uint8)),
     "same kind of dtype, got float32 and uint8"),
    (lambda: metrics.psnr(IMAGE[0], IMAGE[0]), r"must have shape \[\.\.\., H, W, C\]"),
    (lambda: metrics.make_lpips("vgg"), "net must be one of"),
])
def test_metric_argument_table(call, message):
  with pytest.raises(ValueError, match=message):
    call()


def test_integer_images_are_compared_in_floats_with_their_dtype_peak():
  """uint8 arithmetic wraps (0 - 1 = 255) and a peak of 1 for 0..255 values gives about
  -40 dB: integer images are compared as floats, with max_val = the dtype's maximum."""
  a = np.zeros((4, 4, 3), np.uint8)
  b = np.full((4, 4, 3), 255, np.uint8)
  assert float(metrics.mse(a, b)) == 255.0 ** 2
  assert float(metrics.mse(b, a)) == 255.0 ** 2  # not (0 - 255) mod 256
  q = np.round(IMAGE * 255).astype(np.uint8)
  noisy = np.clip(q.astype(int) + np.random.default_rng(1).integers(-3, 4, q.shape), 0,
                  255).astype(np.uint8)
  as_float = metrics.psnr(q / 255.0, noisy / 255.0)
  np.testing.assert_allclose(float(metrics.psnr(q, noisy)), float(as_float), rtol=1e-5)
  assert 30 < float(metrics.psnr(q, noisy)) < 60
  np.testing.assert_allclose(float(metrics.ssim(q, noisy)),
                             float(metrics.ssim(q / 255.0, noisy / 255.0)), rtol=1e-5)
  # An explicit peak is taken as given.
  np.testing.assert_allclose(float(metrics.psnr(q, noisy, max_val=1.0)),
                             float(metrics.psnr(q, noisy)) - 20 * np.log10(255), rtol=1e-5)


def test_top_k_beyond_the_count_returns_all_in_order():
  np.testing.assert_array_equal(top_k([0.1, 0.4, 0.2], 5), [1, 2, 0])
  assert top_k([0.1, 0.4], 0).size == 0


# ====================================================================== atomic writes


def test_a_writer_that_dies_leaves_the_previous_file_and_no_temporary(tmp_path):
  path = tmp_path / "table.md"
  _json.write_text(path, "complete")
  with pytest.raises(RuntimeError), _json.atomic_open(path) as f:
    f.write("half a ta")
    raise RuntimeError("killed mid-write")
  assert path.read_text() == "complete" and sorted(os.listdir(tmp_path)) == ["table.md"]
  with _json.atomic_path(tmp_path / "figure.png") as tmp:  # keeps the extension
    assert tmp.endswith(".png")
    Image.new("RGB", (2, 2)).save(tmp)
  assert sorted(os.listdir(tmp_path)) == ["figure.png", "table.md"]
