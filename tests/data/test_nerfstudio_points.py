"""The point cloud of a nerfstudio capture (`read_points`): colours by their type, read in full."""

import numpy as np
import plyfile
import pytest

from mfsample import orbit_camera
from mfsample.camera import Camera
from mfsample.data import DatasetError, PointCloud, Views, export_nerfstudio
from mfsample.data.nerfstudio import read_points

XYZ = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], np.float32)


def _cloud(path, rgb, text=False):
  """A point-cloud .ply of XYZ with colour properties of `rgb`'s dtype."""
  rgb = np.asarray(rgb)
  table = np.empty(3, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", rgb.dtype),
                             ("green", rgb.dtype), ("blue", rgb.dtype)])
  for j, c in enumerate("xyz"):
    table[c] = XYZ[:, j]
  for j, c in enumerate(("red", "green", "blue")):
    table[c] = rgb[:, j]
  plyfile.PlyData([plyfile.PlyElement.describe(table, "vertex")], text=text).write(str(path))
  return path


@pytest.mark.parametrize("text", [False, True], ids=["binary", "ascii"])
@pytest.mark.parametrize("rgb, want", [
    (np.array([[0, 128, 255]] * 3, np.uint8), [0.0, 128 / 255, 1.0]),
    (np.array([[0, 32768, 65535]] * 3, np.uint16), [0.0, 32768 / 65535, 1.0]),
    (np.array([[0.0, 0.25, 1.0]] * 3, np.float32), [0.0, 0.25, 1.0]),
], ids=["uchar", "ushort", "float"])
def test_colours_are_read_on_their_types_scale(tmp_path, text, rgb, want):
  """A 16-bit colour was divided by 255 and clipped: white."""
  points = read_points(_cloud(tmp_path / "pc.ply", rgb, text))
  np.testing.assert_allclose(points.rgb, np.tile(want, (3, 1)), rtol=1e-6)
  np.testing.assert_array_equal(points.xyz, XYZ)


@pytest.mark.parametrize("rgb, message", [
    (np.array([[10.0, 128.0, 255.0]] * 3, np.float32),
     r"pc\.ply: vertex property red = 10 in row 0 is outside \[0, 1\] \(3 rows\)"),
    (np.array([[0.5, 0.5, 0.5], [0.5, np.nan, 0.5], [0.1, 0.1, 0.1]], np.float32),
     r"vertex property green = nan in row 1 is outside \[0, 1\]"),
    (np.array([[-1, 3, 4]] * 3, np.int16), "vertex property red holds negative colours"),
])
def test_float_colours_outside_0_1_are_refused_not_clipped_to_white(tmp_path, rgb, message):
  with pytest.raises(DatasetError, match=message):
    read_points(_cloud(tmp_path / "pc.ply", rgb))


def test_the_cloud_is_read_in_full(tmp_path):
  path = _cloud(tmp_path / "pc.ply", np.full((3, 3), 9, np.uint8), text=True)
  path.write_bytes(path.read_bytes() + b"5 5 5 1 2 3\n")  # a row the header does not declare
  with pytest.raises(DatasetError, match=r"pc\.ply: the header declares 3 rows \(3 vertex\), "
                                         "but the data holds 4 lines"):
    read_points(path)
  path = _cloud(tmp_path / "pc.ply", np.full((3, 3), 9, np.uint8))
  path.write_bytes(path.read_bytes() + b"\0" * 15)
  with pytest.raises(DatasetError, match=r"pc\.ply: 15 bytes follow the last of the 3 vertex "
                                         "rows"):
    read_points(path)


def test_export_refuses_colours_on_another_scale_before_writing(tmp_path):
  w2c = np.asarray(orbit_camera(0.3, 0.4, width=8, height=8, distance=3.0).world_to_camera)
  views = Views(np.zeros((2, 8, 8, 3), np.float32),
                Camera.create(np.stack([w2c] * 2), 6.0, 6.0, 4.0, 4.0, 8, 8))
  with pytest.raises(ValueError, match=r"points.rgb\[0\] = \[200.0, 200.0, 200.0\] is outside"):
    export_nerfstudio(tmp_path, views, PointCloud(XYZ, np.full((3, 3), 200.0, np.float32)))
  assert not any(tmp_path.iterdir())
