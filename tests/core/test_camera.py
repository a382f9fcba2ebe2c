"""Camera conventions: look_at, from_blender, projection, batching, gradients."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import float64

from mfsample import Camera
from mfsample.camera import InvalidCameraError

UP = jnp.array([0.0, 0.0, 1.0])


def test_look_at_puts_the_target_at_the_image_centre():
  cam = Camera.look_at(jnp.array([2.0, -3.0, 1.5]), jnp.array([0.1, 0.2, -0.3]), UP, 0.8,
                       64, 48)
  uv, z = cam.project(jnp.array([[0.1, 0.2, -0.3]]))
  np.testing.assert_allclose(uv[0], [32.0, 24.0], atol=1e-4)
  np.testing.assert_allclose(z[0], np.linalg.norm([1.9, -3.2, 1.8]), rtol=1e-6)


def test_look_at_is_a_right_handed_opencv_frame():
  cam = Camera.look_at(jnp.array([3.0, 0.0, 0.0]), jnp.zeros(3), UP, 0.8, 32, 32)
  rot = np.asarray(cam.rotation)
  np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-6)
  np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-6)
  uv, _ = cam.project(jnp.array([[0.0, 0.0, 0.5], [0.0, 0.5, 0.0]]))
  assert uv[0, 1] < 16  # world up is image up (smaller row)
  # Looking along -x with z up, world +y is on the image's right.
  assert uv[1, 0] > 16


def test_look_at_handles_viewing_along_up():
  cam = Camera.look_at(jnp.array([0.0, 0.0, 3.0]), jnp.zeros(3), UP, 0.8, 8, 8)
  assert np.all(np.isfinite(np.asarray(cam.world_to_camera)))
  uv, _ = cam.project(jnp.zeros((1, 3)))
  np.testing.assert_allclose(uv[0], [4.0, 4.0], atol=1e-5)


def test_from_blender_matches_a_hand_computed_projection():
  # Blender camera at (0, -4, 0) looking along +y: camera x -> world +x, camera y (up) ->
  # world +z, camera z (backward) -> world -y.
  c2w = np.array([[1.0, 0.0, 0.0, 0.0],
                  [0.0, 0.0, -1.0, -4.0],
                  [0.0, 1.0, 0.0, 0.0],
                  [0.0, 0.0, 0.0, 1.0]])
  fov, w, h = 0.7, 80, 60
  cam = Camera.from_blender(c2w, fov, w, h)
  point = np.array([0.5, 0.0, 0.25])  # 4 ahead, 0.5 right, 0.25 up
  f = 0.5 * w / np.tan(0.5 * fov)
  expected = [f * 0.5 / 4.0 + w / 2, -f * 0.25 / 4.0 + h / 2]
  uv, z = cam.project(jnp.asarray(point[None]))
  np.testing.assert_allclose(uv[0], expected, rtol=1e-6)
  np.testing.assert_allclose(z[0], 4.0, rtol=1e-6)
  np.testing.assert_allclose(cam.center, [0.0, -4.0, 0.0], atol=1e-6)
  np.testing.assert_allclose(cam.camera_to_world[:3, 3], [0.0, -4.0, 0.0], atol=1e-6)
  # A 3x4 matrix is accepted too.
  np.testing.assert_allclose(Camera.from_blender(c2w[:3], fov, w, h).world_to_camera,
                             cam.world_to_camera)


def test_batched_cameras_index_and_vmap():
  eyes = jnp.array([[3.0, 0.0, 1.0], [0.0, 3.0, 1.0], [-3.0, 0.0, 1.0]])
  cams = Camera.look_at(eyes, jnp.zeros(3), UP, 0.9, 20, 10)
  assert cams.batch_shape == (3,) and len(cams) == 3
  one = cams[1]
  np.testing.assert_allclose(one.center, eyes[1], atol=1e-6)
  uv = jax.vmap(lambda c: c.project(jnp.zeros((1, 3)))[0])(cams)
  np.testing.assert_allclose(uv[:, 0], np.tile([10.0, 5.0], (3, 1)), atol=1e-4)


@pytest.mark.slow
def test_gradient_through_look_at_matches_finite_differences():
  point = jnp.array([[0.3, -0.2, 0.4]])

  def f(eye):
    cam = Camera.look_at(eye, jnp.zeros(3), UP, 0.9, 32, 32)
    uv, z = cam.project(point)
    return jnp.sum(uv * jnp.array([1.0, 2.0])) + z[0]

  with float64():
    eye = jnp.array([2.0, -2.5, 1.2])
    grad = jax.grad(f)(eye)
    for i in range(3):
      e = jnp.zeros(3).at[i].set(1e-6)
      fd = (f(eye + e) - f(eye - e)) / 2e-6
      np.testing.assert_allclose(grad[i], fd, rtol=1e-5)


@pytest.mark.parametrize("width, height", [(0, 4), (4, -1), (2.5, 4)])
def test_invalid_sizes_raise(width, height):
  with pytest.raises(ValueError, match="integer >= 1"):
    Camera.create(jnp.eye(4), 1.0, 1.0, 0.0, 0.0, width, height)


def test_bad_matrix_shape_raises():
  with pytest.raises(ValueError, match="4, 4"):
    Camera.create(jnp.eye(3), 1.0, 1.0, 0.0, 0.0, 4, 4)


# ---------------------------------------------------------------------- far cameras


@pytest.mark.parametrize("eye, target, message", [
    ([1e20, 0.0, 0.0], [0.0, 0.0, 0.0], r"eye is out of range \(a coordinate of magnitude "
                                        r"1e\+20\); positions must lie within 1e\+18"),
    ([0.0, 0.0, -3e19], [0.0, 0.0, 0.0], r"eye is out of range \(a coordinate of magnitude 3e\+19"),
    ([3.0, 0.0, 1.0], [0.0, 1e20, 0.0], "target is out of range"),
    ([[3.0, 0.0, 1.0], [0.0, 5e18, 0.0]], [0.0, 0.0, 0.0], "eye is out of range"),
    ([np.inf, 0.0, 0.0], [0.0, 0.0, 0.0], r"eye has non-finite entries \(\[inf, 0.0, 0.0\]\)"),
    ([3.0, 0.0, 1.0], [np.nan, 0.0, 0.0], "target has non-finite entries"),
])
def test_a_far_eye_or_target_is_out_of_range_not_a_non_rigid_rotation(eye, target, message):
  """At 1e20 float32 squares of the distance overflow, the rotation came out zero, and the
  error spoke of a non-rigid pose."""
  with pytest.raises(InvalidCameraError, match=message) as error:
    Camera.look_at(np.array(eye), np.array(target), np.array([0.0, 0.0, 1.0]), 0.8, 8, 8)
  assert "rigid" not in str(error.value)


def test_far_translations_are_out_of_range_in_every_constructor_and_invalid_under_jit():
  w2c = np.eye(4)
  w2c[0, 3] = 1e20
  with pytest.raises(InvalidCameraError, match=r"world_to_camera has the translation "
                                               r"\[1e\+20, 0, 0\], out of range"):
    Camera.create(w2c, 8.0, 8.0, 4.0, 4.0, 8, 8)
  c2w = np.eye(4)
  c2w[2, 3] = -2e19
  with pytest.raises(InvalidCameraError, match="out of range"):
    Camera.from_blender(c2w, 0.8, 8, 8)
  flags = jax.jit(lambda m: Camera(m, jnp.full(2, 8.0), jnp.full(2, 8.0), jnp.full(2, 4.0),
                                   jnp.full(2, 4.0), 8, 8).valid)
  near = np.eye(4)
  near[2, 3] = 1e17  # within the limit: a valid, if distant, camera
  np.testing.assert_array_equal(flags(jnp.asarray(np.stack([near, w2c]), jnp.float32)),
                                [True, False])
  far = Camera.look_at(np.array([1e17, 0.0, 0.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]), 0.8,
                       8, 8)
  assert far.problems() == [] and bool(far.valid)
