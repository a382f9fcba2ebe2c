"""Tests of mfsample.scenes: descriptions, meshes, cameras, cache, and Mitsuba captures.

Captures run at tiny sizes (16x16 to 48x40, few spp) and only when Mitsuba is importable.
"""

import subprocess
import sys
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import mfsample
from mfsample.camera import Camera
from mfsample.data import export_blender, load_blender
from mfsample.renderer.sh import sh_basis
from mfsample.scenes import (
    SCENES,
    Lighting,
    Material,
    Scene,
    Shape,
    cache,
    capture,
    capture_sh_basis,
    capture_views,
    get_scene,
    meshes,
    relight,
    sh_environment_texels,
)
from mfsample.scenes import mitsuba_bridge as bridge

needs_mitsuba = pytest.mark.skipif(not bridge.mitsuba_available(),
                                   reason="mitsuba not installed (extra 'scenes')")
UP = np.array([0.0, 0.0, 1.0], np.float32)


def _pixel_grid(height, width):
  ii, jj = np.mgrid[:height, :width]
  return ii + 0.5, jj + 0.5


def _centroid(weights):
  ii, jj = _pixel_grid(*weights.shape)
  return np.array([(weights * jj).sum(), (weights * ii).sum()]) / weights.sum()


# ------------------------------------------------------------------ without Mitsuba


def test_import_does_not_import_mitsuba():
  code = ("import sys, mfsample, mfsample.scenes, mfsample.data; "
          "mfsample.scenes.get_scene().candidate_cameras(8, 8, num=2); "
          "assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules")
  subprocess.run([sys.executable, "-c", code], check=True)


def test_capture_without_mitsuba_says_how_to_install(tmp_path, monkeypatch):
  monkeypatch.setitem(sys.modules, "mitsuba", None)  # makes `import mitsuba` fail
  scene = get_scene()
  with pytest.raises(ImportError, match=r'pip install "mfsample\[scenes\]"'):
    capture(scene, scene.test_cameras(8, 8, num=1)[0], spp=1, cache_dir=tmp_path)


def test_scene_registry():
  assert "default" in SCENES and len(SCENES) >= 3
  assert get_scene().name == get_scene("tabletop").name
  with pytest.raises(ValueError, match="unknown scene 'nope'.*tabletop"):
    get_scene("nope")


@pytest.mark.parametrize("name", [n for n in SCENES if n != "default"])
def test_scenes_are_rich_tabletops(name):
  scene = get_scene(name)
  assert scene.up == (0.0, 0.0, 1.0) and np.allclose(scene.center, 0.0)
  assert scene.bounding_error() <= 0.0, "a shape sticks out of the bounding sphere"
  assert 0.5 <= scene.radius <= 1.5
  kinds = {s.material.kind for s in scene.shapes}
  assert "diffuse" in kinds and kinds & {"plastic", "conductor"}  # diffuse and glossy
  assert any(s.material.checker is not None for s in scene.shapes)  # textured
  assert {s.kind for s in scene.shapes} & {"bowl", "cup"}  # a concavity
  assert len(scene.shapes) >= 6
  # The camera sphere sees the whole bounding sphere.
  assert np.arcsin(scene.radius / scene.camera_distance) < 0.5 * scene.fov_x


def test_fingerprint_tracks_every_parameter():
  scene = get_scene()
  assert scene.fingerprint() == get_scene().fingerprint()
  moved = Shape(**{**scene.shapes[1].__dict__, "position": (0.0, 0.0, -0.2)})
  edited = Scene(**{**scene.__dict__, "shapes": (scene.shapes[0], moved) + scene.shapes[2:]})
  assert edited.fingerprint() != scene.fingerprint()
  relit = Scene(**{**scene.__dict__, "lighting": Lighting(ambient=0.1)})
  assert relit.fingerprint() != scene.fingerprint()


@pytest.mark.parametrize("name", sorted(meshes.GENERATORS))
def test_meshes_are_closed_and_outward(name):
  mesh = meshes.GENERATORS[name]()
  assert meshes.signed_volume(mesh) > 0
  p = mesh.vertices.astype(np.float64)[mesh.faces]
  face_n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
  face_n /= np.linalg.norm(face_n, axis=-1, keepdims=True)
  # Shading normals agree with the winding (one-sided BSDFs would render black otherwise).
  assert np.min(np.einsum("fki,fi->fk", mesh.normals[mesh.faces], face_n)) > 0.9
  np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=-1), 1.0, atol=1e-5)
  assert mesh.uvs.min() >= -1e-6 and mesh.uvs.max() <= 1 + 1e-6
  # A mirroring transform keeps the winding outward.
  assert meshes.signed_volume(mesh.transformed(np.diag([-1.0, 1.0, 1.0, 1.0]))) > 0


def test_candidate_and_test_cameras():
  scene = get_scene()
  cands = scene.candidate_cameras(32, 24, num=100)
  tests = scene.test_cameras(32, 24, num=50)
  assert cands.batch_shape == (100,) and tests.batch_shape == (50,)
  assert (cands.width, cands.height) == (32, 24)
  for cams in (cands, tests):
    centers = np.asarray(cams.center)
    np.testing.assert_allclose(np.linalg.norm(centers, axis=-1), scene.camera_distance,
                               rtol=1e-5)
    polar = np.arccos(centers[:, 2] / scene.camera_distance)
    assert np.all(polar >= scene.polar_range[0] - 1e-5)
    assert np.all(polar <= scene.polar_range[1] + 1e-5)
    uv, z = cams.project(np.zeros((1, 3), np.float32))  # they look at the centre
    np.testing.assert_allclose(np.asarray(uv)[:, 0], [[16.0, 12.0]] * len(centers), atol=1e-3)
    # Up = +z: a point above the centre is above the image centre.
    uv_up, _ = cams.project(np.array([[0.0, 0.0, 0.3]], np.float32))
    assert np.all(np.asarray(uv_up)[:, 0, 1] < 12.0)
  # Held out: no test pose is a candidate pose, whatever the seeds.
  gaps = np.linalg.norm(np.asarray(tests.center)[:, None] - np.asarray(cands.center)[None],
                        axis=-1)
  assert gaps.min() > 1e-3
  same_seed = scene.test_cameras(32, 24, num=50, seed=0)
  assert not np.allclose(np.asarray(same_seed.center), np.asarray(cands.center)[:50])
  np.testing.assert_array_equal(np.asarray(scene.candidate_cameras(32, 24).world_to_camera),
                                np.asarray(cands.world_to_camera))


def test_camera_at_matches_authors_parameterisation():
  scene = get_scene()
  cam = scene.camera_at(np.pi / 2, np.pi / 3, 16, 16)
  d = scene.camera_distance
  np.testing.assert_allclose(np.asarray(cam.center),
                             [0.0, d * np.sin(np.pi / 3), d * np.cos(np.pi / 3)], atol=1e-5)


def test_cache_keys_and_atomic_files(tmp_path, monkeypatch):
  scene = get_scene()
  cams = scene.test_cameras(8, 8, num=2)
  key = cache.capture_key("rgbad", scene, cams[0], spp=4, variant="scalar_rgb")
  assert key == cache.capture_key("rgbad", scene, cams[0], spp=4, variant="scalar_rgb")
  others = {
      cache.capture_key("rgbad", scene, cams[1], spp=4, variant="scalar_rgb"),
      cache.capture_key("rgbad", scene, cams[0], spp=9, variant="scalar_rgb"),
      cache.capture_key("rgbad", scene, cams[0], spp=4, variant="llvm_ad_rgb"),
      cache.capture_key("sh_basis", scene, cams[0], spp=4, variant="scalar_rgb"),
      cache.capture_key("rgbad", get_scene("still_life"), cams[0], spp=4,
                        variant="scalar_rgb"),
      cache.capture_key("rgbad", scene, scene.test_cameras(16, 8, num=1)[0], spp=4,
                        variant="scalar_rgb"),
  }
  assert key not in others and len(others) == 6
  path = cache.entry_path(tmp_path, scene, "rgbad", key)
  assert cache.load(path) is None
  cache.save(path, {"a": np.arange(3.0)})
  np.testing.assert_array_equal(cache.load(path)["a"], np.arange(3.0))
  assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary left
  path.write_bytes(b"not a zip")
  with pytest.warns(UserWarning, match="unreadable cache entry"):
    assert cache.load(path) is None
  monkeypatch.setenv("MFSAMPLE_CACHE", str(tmp_path / "elsewhere"))
  assert cache.default_cache_dir() == tmp_path / "elsewhere"


def test_variant_resolution(monkeypatch):
  monkeypatch.delenv(bridge.VARIANT_ENV, raising=False)
  assert bridge.resolve_variant() == "scalar_rgb"
  monkeypatch.setenv(bridge.VARIANT_ENV, "llvm_ad_rgb")
  assert bridge.resolve_variant() == "llvm_ad_rgb"
  assert bridge.resolve_variant("scalar_rgb") == "scalar_rgb"
  with pytest.raises(ValueError, match="variant"):
    bridge.resolve_variant("cuda_ad_spectral")


def test_relight_is_the_linear_combination():
  rng = np.random.default_rng(0)
  basis = rng.normal(size=(4, 3, 2, 3)).astype(np.float32)
  xi = rng.normal(size=4)
  np.testing.assert_allclose(relight(basis, xi), np.tensordot(xi, basis, axes=1), rtol=1e-5)
  xi_rgb = rng.normal(size=(4, 3))
  np.testing.assert_allclose(relight(basis, xi_rgb)[..., 1],
                             np.tensordot(xi_rgb[:, 1], basis[..., 1], axes=1), rtol=1e-5)


def test_sh_texels_use_the_renderer_basis():
  dirs = bridge.texel_directions(8, 16)
  np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=1e-6)
  texels = sh_environment_texels(3, 8, 16)
  np.testing.assert_allclose(np.moveaxis(texels, 0, -1),
                             np.asarray(sh_basis(jnp.asarray(dirs, jnp.float32), 3)),
                             atol=1e-6)
  assert np.allclose(dirs[0], [0.0, 0.0, 1.0], atol=1e-6)  # first row: the +z pole


# ------------------------------------------------------------------ Mitsuba captures


def _probe_scene(point, radius):
  """One small white sphere at `point`, evenly lit."""
  return Scene("probe", (Shape("dot", "sphere", Material("diffuse", (1.0, 1.0, 1.0)),
                               position=tuple(float(x) for x in point),
                               scale=(radius,) * 3),),
               lighting=Lighting(ambient=1.0, sun_irradiance=0.0), max_depth=2)


@needs_mitsuba
def test_known_point_lands_on_the_same_pixel_as_the_renderer(tmp_path):
  width, height = 48, 40
  point = np.array([0.3, -0.2, 0.25], np.float32)
  cam = Camera.look_at(np.array([2.0, -3.0, 2.0], np.float32), np.zeros(3, np.float32), UP,
                       np.radians(40.0), width, height)
  # An off-centre principal point checks Mitsuba's principal_point_offset convention.
  cam = Camera.create(cam.world_to_camera, cam.fx, cam.fy, 21.3, 23.7, width, height)
  uv, z = cam.project(point[None])
  uv, z = np.asarray(uv)[0], float(z[0])
  _, alpha, depth = capture(_probe_scene(point, 0.06), cam, spp=64, cache_dir=tmp_path)
  np.testing.assert_allclose(_centroid(alpha), uv, atol=0.1)  # pixels
  pixel = (int(uv[1]), int(uv[0]))
  assert np.unravel_index(alpha.argmax(), alpha.shape) == pixel
  assert abs(depth[pixel] - (z - 0.06)) < 0.01  # the sphere's front, in camera z
  # mfsample.render of a tiny Gaussian at the same point peaks at the same pixel.
  g = mfsample.Gaussians(means=jnp.asarray(point[None]), scales=jnp.full((1, 3), 0.01),
                         quats=jnp.array([[1.0, 0.0, 0.0, 0.0]]), opacities=jnp.array([0.9]),
                         sh=jnp.zeros((1, 1, 3)))
  out = mfsample.render(g, cam, settings=mfsample.RenderSettings(max_intersections=512))
  assert not bool(out.stats.overflow)
  rendered = np.asarray(out.alpha)
  assert np.unravel_index(rendered.argmax(), rendered.shape) == pixel
  np.testing.assert_allclose(_centroid(rendered), uv, atol=0.05)


@needs_mitsuba
def test_depth_is_camera_z_not_ray_length(tmp_path):
  """A plane facing the camera at distance 2: z-depth is 2 at every pixel, including the
  partially covered edge pixels, while ray lengths grow towards the corners by ~6%."""
  width, height = 24, 16
  plane = Scene("plane", (Shape("wall", "rectangle", Material("diffuse"),
                                position=(0.3, -0.1, 0.0), scale=(0.7, 0.5, 1.0)),),
                lighting=Lighting(ambient=1.0, sun_irradiance=0.0), max_depth=2)
  cam = Camera.look_at(np.array([0.2, 0.0, 2.0], np.float32), np.array([0.2, 0.0, 0.0],
                                                                          np.float32),
                       np.array([0.0, 1.0, 0.0], np.float32), np.radians(50.0), width, height)
  rgb, alpha, depth = capture(plane, cam, spp=16, cache_dir=tmp_path)
  assert alpha.max() == 1.0 and alpha.min() == 0.0
  assert np.any((alpha > 0) & (alpha < 1))  # partially covered pixels exist
  np.testing.assert_allclose(depth[alpha > 0], 2.0, rtol=1e-5)
  assert np.all(depth[alpha == 0] == 0.0)
  np.testing.assert_allclose(rgb[alpha == 0], 1.0)  # a clean white background


@needs_mitsuba
def test_capture_views_default_scene(tmp_path, monkeypatch):
  scene = get_scene()
  cams = scene.candidate_cameras(16, 16, num=2)
  views = capture_views(scene, cams, spp=4, cache_dir=tmp_path, progress=False)
  assert views.images.shape == (2, 16, 16, 3) and views.images.dtype == np.float32
  assert views.alphas.shape == views.depths.shape == (2, 16, 16)
  assert np.all((views.images >= 0) & (views.images <= 1))
  assert len(set(views.names)) == 2 and views.names[0].startswith("tabletop-")
  hit = views.alphas > 0.999
  assert hit.any() and np.all(views.alphas[:, 0, 0] == 0)  # corners see the background
  # Hits are inside the bounding sphere: z-depth within distance +- radius.
  d, r = scene.camera_distance, scene.radius
  assert np.all((views.depths[hit] > d - r) & (views.depths[hit] < d + r))
  # Captured again: read from the cache, Mitsuba is not called.
  monkeypatch.setattr(bridge, "render", lambda *a, **k: pytest.fail("not cached"))
  again = capture_views(scene, cams, spp=4, cache_dir=tmp_path, progress=False)
  np.testing.assert_array_equal(again.images, views.images)
  np.testing.assert_array_equal(again.depths, views.depths)
  black = capture_views(scene, cams, spp=4, cache_dir=tmp_path, progress=False,
                        background=(0.0, 0.0, 0.0))
  np.testing.assert_allclose(black.images[:, 0, 0], 0.0)


@needs_mitsuba
def test_export_of_captures_round_trips(tmp_path):
  scene = get_scene("still_life")
  views = capture_views(scene, scene.test_cameras(16, 12, num=2), spp=4,
                        cache_dir=tmp_path / "cache", progress=False)
  export_blender(tmp_path / "ds", views, split="test")
  loaded = load_blender(tmp_path / "ds", "test")
  np.testing.assert_allclose(loaded.images, views.images, atol=1.0 / 255 + 1e-6)
  np.testing.assert_allclose(loaded.alphas, views.alphas, atol=0.5 / 255 + 1e-6)
  np.testing.assert_array_equal(loaded.depths, views.depths)
  assert loaded.names == views.names
  np.testing.assert_allclose(np.asarray(loaded.cameras.world_to_camera),
                             np.asarray(views.cameras.world_to_camera), atol=1e-6)


@needs_mitsuba
def test_capture_rejects_what_it_cannot_render(tmp_path):
  scene = get_scene()
  cam = scene.test_cameras(8, 8, num=1)[0]
  with pytest.raises(ValueError, match="perfect square"):
    capture(scene, cam, spp=8, cache_dir=tmp_path)
  stretched = Camera.create(cam.world_to_camera, cam.fx, cam.fx * 1.1, cam.cx, cam.cy, 8, 8)
  with pytest.raises(ValueError, match="square pixels"):
    capture(scene, stretched, spp=1, cache_dir=tmp_path)
  with pytest.raises(ValueError, match="capture_views"):
    capture(scene, scene.test_cameras(8, 8, num=2), spp=1, cache_dir=tmp_path)


@needs_mitsuba
def test_envmap_texel_layout_matches_mitsuba():
  """Our model of Mitsuba's envmap lookup (texel directions + bilinear) against
  `Emitter.eval` at random directions, without Monte Carlo."""
  mi = bridge.set_variant("scalar_rgb")
  h, w = 8, 16
  rng = np.random.default_rng(0)
  texels = rng.uniform(0.0, 1.0, (h, w)).astype(np.float32)
  mi_scene = bridge.build_scene(Scene("sky", ()), "scalar_rgb",
                                environment=np.repeat(texels[..., None], 3, -1))
  emitter = mi_scene.emitters()[0]
  for d in rng.normal(size=(100, 3)):
    d /= np.linalg.norm(d)
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*(-d))  # eval() looks along -wi
    local = bridge.ENV_TO_WORLD.T @ d
    x = (np.arctan2(local[0], -local[2]) / (2 * np.pi) % 1.0) * w - 0.5
    y = np.arccos(np.clip(local[1], -1.0, 1.0)) / np.pi * (h - 1)
    x0, y0 = int(np.floor(x)), min(int(np.floor(y)), h - 2)
    fx, fy = x - x0, y - y0
    t = lambda r, c: texels[r, c % w]
    expected = ((1 - fy) * ((1 - fx) * t(y0, x0) + fx * t(y0, x0 + 1))
                + fy * ((1 - fx) * t(y0 + 1, x0) + fx * t(y0 + 1, x0 + 1)))
    assert emitter.eval(si)[0] == pytest.approx(expected, abs=1e-5)


@needs_mitsuba
def test_visible_environment_matches_the_function_of_world_direction():
  """Camera rays that escape see L(d) = f(d) for the world direction d: checks the envmap
  orientation and the camera conversion together."""
  width, height = 16, 12
  f = lambda d: 1.2 + 0.6 * d[..., 0] - 0.3 * d[..., 1] + 0.8 * d[..., 2]
  mi_scene = bridge.build_scene(Scene("sky", ()), "scalar_rgb",
                                environment=bridge.environment_texels(f, 64, 128),
                                visible_environment=True)
  cam = Camera.look_at(np.zeros(3, np.float32), np.array([1.0, 2.0, 0.7], np.float32), UP,
                       np.radians(90.0), width, height)
  out = bridge.render(mi_scene, bridge.sensor(cam, 16, "scalar_rgb"), 16, 0)
  ii, jj = _pixel_grid(height, width)
  rays = np.stack([(jj - float(cam.cx)) / float(cam.fx), (ii - float(cam.cy)) / float(cam.fy),
                   np.ones_like(ii)], -1) @ np.asarray(cam.rotation, np.float64)
  expected = f(rays / np.linalg.norm(rays, axis=-1, keepdims=True))
  np.testing.assert_allclose(out["radiance"][..., 0], expected, atol=0.02)


@needs_mitsuba
def test_sh_superposition_matches_a_direct_render(tmp_path):
  """sum_j xi_j I_j equals the render under the environment sum_j xi_j Y_j within MC noise
  (on 4x4 blocks, where the noise of the 31 signed basis renders averages down)."""
  scene = get_scene()
  cam = scene.candidate_cameras(16, 16, num=1)[0]
  rng = np.random.default_rng(0)
  xi = 0.25 * rng.normal(size=16)
  xi[0] = 1.0 / 0.28209479177387814  # + 1 everywhere: the environment stays positive
  basis = capture_sh_basis(scene, cam, degree=3, spp=64, cache_dir=tmp_path)
  assert basis.shape == (16, 16, 16, 3) and basis.dtype == np.float32
  texels = np.einsum("khw,k->hw", sh_environment_texels(3), xi)
  assert texels.min() > 0
  mi_scene = bridge.build_scene(scene, "scalar_rgb",
                                environment=np.repeat(texels[..., None], 3, -1))
  direct = bridge.render(mi_scene, bridge.sensor(cam, 256, "scalar_rgb"), 256, 1)["radiance"]
  relit = relight(basis, xi)
  block = lambda x: x.reshape(4, 4, 4, 4, 3).mean(axis=(1, 3))
  assert abs(relit.mean() / direct.mean() - 1.0) < 0.02
  assert np.sqrt(np.mean((block(relit) - block(direct)) ** 2)) < 0.006
  # A wrong sign (light from below instead of above) is far outside that noise.
  flipped = relight(basis, xi * np.where(np.arange(16) == 2, -1.0, 1.0))
  assert np.sqrt(np.mean((block(flipped) - block(direct)) ** 2)) > 0.01
  # Cached: the second call reads the file.
  with warnings.catch_warnings():
    warnings.simplefilter("error")
    np.testing.assert_array_equal(capture_sh_basis(scene, cam, spp=64, cache_dir=tmp_path),
                                  basis)


@needs_mitsuba
@pytest.mark.skipif(not bridge.llvm_available(),
                    reason="llvm_ad_rgb needs the LLVM library (Debian: libllvm19)")
def test_llvm_variant_agrees_with_scalar(tmp_path):
  scene = get_scene()
  cam = scene.candidate_cameras(16, 16, num=1)[0]
  a_rgb, a_alpha, a_depth = capture(scene, cam, spp=16, cache_dir=tmp_path,
                                    variant="scalar_rgb")
  b_rgb, b_alpha, b_depth = capture(scene, cam, spp=16, cache_dir=tmp_path,
                                    variant="llvm_ad_rgb")
  assert abs(a_rgb.mean() - b_rgb.mean()) < 0.01
  assert np.mean(np.abs(a_alpha - b_alpha)) < 0.02
  both = (a_alpha == 1) & (b_alpha == 1)
  # Pixels straddling a depth edge differ by their noise; the typical pixel agrees.
  assert np.median(np.abs(a_depth[both] / b_depth[both] - 1.0)) < 0.005
