"""Any 3DGS .ply to PNG: the file's Gaussians as the renderer draws them, from an orbit or a
3DGS camera list, or coloured by a per-Gaussian property."""

import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import jax.numpy as jnp
import numpy as np
import pytest

from mfsample import render
from mfsample.data import DatasetError
from mfsample.data.camera_export import export_cameras
from mfsample.data.ply import export_gaussians, write_ply
from mfsample.renderer import RenderSettings
from mfsample.testing import random_gaussians
from mfsample.your_data.render_ply import (
  inria_camera_list,
  orbit_around,
  render_ply,
  tile,
)

ROOT = Path(__file__).resolve().parents[2]
SETTINGS = RenderSettings(max_intersections=1 << 14)


@pytest.fixture(scope="module")
def ply(tmp_path_factory):
  gaussians = random_gaussians(300, sh_degree=1, seed=2)
  path = export_gaussians(tmp_path_factory.mktemp("ply") / "model.ply", gaussians)
  return gaussians, path


@pytest.mark.slow
def test_the_file_renders_as_its_gaussians_from_an_orbit(ply):
  gaussians, path = ply
  cameras = orbit_around(np.asarray(gaussians.means), 2, width=40, height=30)
  centre = np.median(np.asarray(gaussians.means), axis=0)
  for i in range(2):  # each camera looks at the Gaussians' median
    _, depth = cameras[i].project(jnp.asarray(centre[None], jnp.float32))
    uv, _ = cameras[i].project(jnp.asarray(centre[None], jnp.float32))
    np.testing.assert_allclose(np.asarray(uv)[0], [20.0, 15.0], atol=1e-3)
    assert float(depth[0]) > 0
  images = render_ply(path, cameras, settings=SETTINGS)
  want = render(gaussians, cameras[1], background=jnp.zeros(3), settings=SETTINGS)
  np.testing.assert_allclose(images[1], np.clip(np.asarray(want.rgb), 0, 1), atol=1e-5)
  assert tile(images, gap=2).shape == (30, 82, 3)


@pytest.mark.slow
def test_colour_by_a_companion_property(ply, tmp_path):
  """Colouring by a property: Gaussians of the largest value are bright, of 0 black."""
  gaussians, path = ply
  means = np.asarray(gaussians.means)
  value = np.where(means[:, 0] > 0, 1.0, 0.0)  # the +x half holds the property
  extras = write_ply(tmp_path / "per_gaussian.ply", {"x": means[:, 0], "y": means[:, 1],
                                                    "z": means[:, 2], "u_share": value})
  camera = orbit_around(means, 1, width=48, height=48, elevation_deg=89.0)[0]  # from above
  (image,) = render_ply(path, [camera], colour_by="u_share", properties=extras,
                        settings=SETTINGS)
  uv, _ = camera.project(jnp.asarray(means, jnp.float32))
  uv = np.asarray(uv)
  brightness = image.sum(-1)
  col = lambda m: np.clip(np.round(np.median(uv[m], axis=0)).astype(int), 0, 47)
  hot, cold = col(value > 0), col(value == 0)
  assert brightness[hot[1], hot[0]] > 4 * brightness[cold[1], cold[0]] + 0.1
  with pytest.raises(DatasetError, match="no vertex property 'nope'.*u_share"):
    render_ply(path, [camera], colour_by="nope", properties=extras)


def test_a_3dgs_camera_list_is_read_back(ply, tmp_path):
  gaussians, _ = ply
  cameras = orbit_around(np.asarray(gaussians.means), 3, width=40, height=30)
  export_cameras(tmp_path / "views", cameras)
  read, names = inria_camera_list(tmp_path / "views" / "cameras.json")
  assert names == ["view_000", "view_001", "view_002"]
  for i, camera in enumerate(read):
    np.testing.assert_allclose(camera.world_to_camera, cameras[i].world_to_camera, atol=1e-5)
    assert (camera.width, camera.height, float(camera.cx)) == (40, 30, 20.0)
  half, _ = inria_camera_list(tmp_path / "views" / "cameras.json", scale=0.5)
  assert (half[0].width, half[0].height) == (20, 15)
  np.testing.assert_allclose(half[0].fx, 0.5 * cameras[0].fx)
  (tmp_path / "bad.json").write_text('[{"width": 4}]')
  with pytest.raises(DatasetError, match=r"bad\.json: camera 0: needs width, height"):
    inria_camera_list(tmp_path / "bad.json")


@pytest.mark.slow
def test_the_command_writes_a_png(ply, tmp_path):
  _, path = ply
  out = tmp_path / "views.png"
  run = subprocess.run([sys.executable, str(ROOT / "experiments" / "render_ply.py"),
                        f"--ply={path}", f"--out={out}", "--views=3", "--size=32,24"],
                       capture_output=True, text=True, timeout=300)
  assert run.returncode == 0, run.stderr
  assert iio.imread(out).shape == (24, 3 * 32 + 2 * 4, 3)
  bad = subprocess.run([sys.executable, str(ROOT / "experiments" / "render_ply.py"),
                        f"--ply={tmp_path / 'missing.ply'}", f"--out={out}"],
                       capture_output=True, text=True, timeout=300)
  assert bad.returncode == 1 and bad.stderr.strip().splitlines()[-1].startswith(
      "error: .ply file not found")


def test_the_installed_command_refuses_a_call_without_its_file_in_one_line():
  """`mfsample render-ply` (`render_ply_command`): --ply and --out are required."""
  run = subprocess.run([sys.executable, "-m", "mfsample", "render-ply", "--out=x.png"],
                       capture_output=True, text=True, timeout=120)
  assert run.returncode == 1 and "Traceback" not in run.stderr
  assert "--ply" in run.stderr
