"""Tests of mfsample.data.ply: the standard 3DGS layout through plyfile, both ways."""

import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import plyfile
import pytest
from ply_testlib import fixed_records

from mfsample import orbit_camera
from mfsample.data import DatasetError
from mfsample.data.ply import (
  export_gaussians,
  export_ply,
  load_ply,
  ply_arrays,
  read_ply_data,
  read_vertex_table,
  sh_degree_of,
  write_gaussians_ply,
)
from mfsample.groups import GROUPS
from mfsample.model import init_model, mean_gaussians, model_from_mean
from mfsample.renderer import RenderSettings, render
from mfsample.samplers import SamplerSpec
from mfsample.testing import random_gaussians

SPEC = SamplerSpec(kind="lowrank", rank=2, groups=("means",), bounds=(("means", 1.0),))
SCALES = {g: 1e-3 for g in GROUPS}


def _model(sh_degree, n=5):
  rng = np.random.default_rng(sh_degree)
  model = init_model(jax.random.PRNGKey(0), rng.uniform(-1, 1, (n, 3)), spec=SPEC,
                     sh_degree=sh_degree, init_scales=SCALES, capacity=n + 3)
  mean = dict(model.params.mean)
  # Distinct, non-trivial values everywhere (the initial model has zero SH rest and
  # identical opacities), so any mix-up of properties or of the f_rest order shows.
  for g in mean:
    if g != "means":
      live = rng.normal(size=(n,) + mean[g].shape[1:]).astype(np.float32)
      mean[g] = mean[g].at[:n].set(live)
  return model.replace(params=model.params._replace(mean=mean))


def _write(path, columns, text=False, byte_order="<"):
  """A PLY vertex element from {name: array}, each with its own numpy dtype."""
  n = len(next(iter(columns.values())))
  table = np.empty(n, dtype=[(k, np.asarray(v).dtype) for k, v in columns.items()])
  for k, v in columns.items():
    table[k] = v
  plyfile.PlyData([plyfile.PlyElement.describe(table, "vertex")], text=text,
                  byte_order=byte_order).write(str(path))
  return path


# The reference layout's properties, in order.
REFERENCE = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
             + [f"f_rest_{i}" for i in range(45)] + ["opacity"]
             + [f"scale_{i}" for i in range(3)] + [f"rot_{i}" for i in range(4)])


@pytest.mark.parametrize("sh_degree", [0, 1, 3])
def test_layout_is_the_reference_one(tmp_path, sh_degree):
  path = tmp_path / "model.ply"
  export_ply(path, _model(sh_degree=sh_degree))
  header = path.read_bytes().split(b"end_header")[0].decode()
  names = [line.split()[-1] for line in header.splitlines() if line.startswith("property")]
  assert names == REFERENCE
  assert "format binary_little_endian 1.0" in header and "element vertex 5" in header
  assert all(line.split()[1] == "float" for line in header.splitlines()
             if line.startswith("property"))
  assert len(path.read_bytes().split(b"end_header\n")[1]) == 5 * 62 * 4  # nothing after


@pytest.mark.parametrize("sh_degree", [1, 3])
def test_fixed_records_hold_the_model(tmp_path, sh_degree):
  """Read as fixed 62-float records, the file gives the model's positions, SH (padded with
  zeros per channel to degree 3), opacities, scales and rotations, normals zero."""
  model = _model(sh_degree)
  path = export_ply(tmp_path / "model.ply", model)
  records = fixed_records(path)
  mean = {g: np.asarray(v)[:5] for g, v in model.params.mean.items()}
  np.testing.assert_array_equal(records[:, 0:3], mean["means"])
  np.testing.assert_array_equal(records[:, 3:6], 0.0)
  np.testing.assert_array_equal(records[:, 6:9], mean["sh_dc"])
  rest = records[:, 9:54].reshape(5, 3, 15)  # [N, channel, coefficient]
  k = (sh_degree + 1) ** 2 - 1
  np.testing.assert_array_equal(rest[:, :, :k], np.transpose(mean["sh_rest"], (0, 2, 1)))
  np.testing.assert_array_equal(rest[:, :, k:], 0.0)
  np.testing.assert_array_equal(records[:, 54], mean["opacity_logits"])
  np.testing.assert_array_equal(records[:, 55:58], mean["log_scales"])
  np.testing.assert_array_equal(records[:, 58:62], mean["quats"])


def test_the_degree_comes_back_from_the_comment_only_over_zero_padding(tmp_path):
  """A degree-1 model is written padded and read as degree 1; a file whose higher bands
  hold values (another tool edited it) is read with all of them; without the comment (the
  reference code's files) the f_rest count decides."""
  path = export_ply(tmp_path / "model.ply", _model(sh_degree=1))
  assert b"comment sh_degree 1" in path.read_bytes().split(b"end_header")[0]
  assert load_ply(path)["sh_rest"].shape == (5, 3, 3)
  table = read_vertex_table(path)
  table["f_rest_20"] = 0.5
  edited = _write(tmp_path / "edited.ply", {k: table[k] for k in table.dtype.names})
  data = edited.read_bytes().replace(b"ply\nformat binary_little_endian 1.0\n",
                                     b"ply\nformat binary_little_endian 1.0\n"
                                     b"comment sh_degree 1\n", 1)
  edited.write_bytes(data)
  assert load_ply(edited)["sh_rest"].shape == (5, 15, 3)
  table = read_vertex_table(path)
  bare = _write(tmp_path / "bare.ply", {k: table[k] for k in table.dtype.names})
  assert load_ply(bare)["sh_rest"].shape == (5, 15, 3)


# The reference code's own file (../shared/data/real beside the checkout, or
# $MFSAMPLE_REAL_DATA): INRIA's point_cloud.ply of 9080 Gaussians, SH degree 3.
INRIA = (Path(os.environ.get("MFSAMPLE_REAL_DATA")
              or Path(__file__).resolve().parents[3] / "shared" / "data" / "real")
         / "inria_ply" / "point_cloud_iter7000.ply")


@pytest.mark.skipif(not INRIA.is_file(), reason=f"INRIA's .ply not found at {INRIA}")
def test_a_reference_file_is_written_back_byte_for_byte(tmp_path):
  """The reference code's file, read and written again: the same records, bit for bit."""
  mean = load_ply(INRIA)
  path = write_gaussians_ply(tmp_path / "again.ply", mean)
  original = fixed_records(INRIA)
  assert original.shape == (9080, 62)
  np.testing.assert_array_equal(fixed_records(path), original)


@pytest.mark.parametrize("sh_degree", [0, 1, 3])
def test_export_import_round_trip_is_exact(tmp_path, sh_degree):
  model = _model(sh_degree)
  path = tmp_path / "model.ply"
  export_ply(path, model)
  mean = load_ply(path)
  live = {g: np.asarray(v)[:5] for g, v in model.params.mean.items()}  # the padding is not written
  assert set(mean) == set(live) and sh_degree_of(mean) == sh_degree
  for g in live:
    np.testing.assert_array_equal(mean[g], live[g], err_msg=g)
    assert mean[g].dtype == np.float32


def test_reads_the_reference_meaning_of_each_property(tmp_path):
  """A file written by hand (not by export_ply), SH degree 1, big-endian doubles, the
  properties shuffled and extra ones (colours, normals, a filter) beside them."""
  n = 3
  rng = np.random.default_rng(1)
  cols = {f"f_rest_{j}": rng.normal(size=n) for j in range(9)}
  cols.update({"scale_2": [-1.0, -2.0, -3.0], "x": [0.1, 0.2, 0.3], "y": [1.0, 2.0, 3.0],
               "z": [-1.0, -2.0, -3.0], "red": np.array([1, 2, 3], np.uint8),
               "opacity": [0.5, -0.5, 2.0], "f_dc_0": [0.1, 0.2, 0.3],
               "f_dc_1": [0.4, 0.5, 0.6], "f_dc_2": [0.7, 0.8, 0.9], "nx": np.zeros(n),
               "scale_0": [-4.0, -5.0, -6.0], "scale_1": [-7.0, -8.0, -9.0],
               "rot_0": [1.0, 0.0, 2.0], "rot_1": [0.0, 1.0, 0.0], "rot_2": [0.0, 0.0, 0.0],
               "rot_3": [0.0, 0.0, 1.0], "filter_3D": [0.01, 0.02, 0.03]})
  cols = {k: (np.asarray(v, ">f8") if np.asarray(v).dtype.kind == "f" else np.asarray(v))
          for k, v in cols.items()}
  mean = load_ply(_write(tmp_path / "hand.ply", cols, byte_order=">"))
  np.testing.assert_allclose(mean["means"][1], [0.2, 2.0, -2.0], rtol=1e-7)
  np.testing.assert_allclose(mean["log_scales"][2], [-6.0, -9.0, -3.0])
  np.testing.assert_allclose(mean["quats"][2], [2.0, 0.0, 0.0, 1.0])  # rot_0 is w
  np.testing.assert_allclose(mean["opacity_logits"], [0.5, -0.5, 2.0])  # raw logits
  np.testing.assert_allclose(mean["sh_dc"][0], [0.1, 0.4, 0.7], rtol=1e-6)
  # f_rest is channel-major: f_rest_0..2 are red's three band-1 coefficients, 3..5 green's.
  assert mean["sh_rest"].shape == (n, 3, 3)
  np.testing.assert_allclose(mean["sh_rest"][:, :, 0], np.stack(
      [cols[f"f_rest_{j}"] for j in range(3)], 1), rtol=1e-6)
  np.testing.assert_allclose(mean["sh_rest"][:, 1, 2], cols["f_rest_7"], rtol=1e-6)


def test_a_loaded_model_renders_as_its_gaussians(tmp_path):
  model = _model(sh_degree=1, n=40)
  path = tmp_path / "model.ply"
  export_ply(path, model)
  loaded = model_from_mean(jax.random.PRNGKey(3), load_ply(path), spec=SPEC,
                           init_scales=SCALES, capacity=model.capacity)  # one compilation
  assert int(loaded.sh_degree) == 1 and loaded.num_live == 40  # every band active
  camera = orbit_camera(0.3, 0.4, width=24, height=20, distance=3.5)
  settings = RenderSettings(max_intersections=1 << 12)
  want = render(mean_gaussians(model.replace(sh_degree=jnp.int32(1))), camera,
                settings=settings)
  got = render(mean_gaussians(loaded), camera, settings=settings)
  assert not bool(got.stats.overflow)
  np.testing.assert_array_equal(np.asarray(got.rgb), np.asarray(want.rgb))


def _reference_columns(n=2, rest=0):
  names = (["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{j}" for j in range(rest)]
           + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
  return {k: np.ones(n, np.float32) for k in names}


def test_malformed_files_are_refused_naming_file_and_property(tmp_path):
  cols = _reference_columns()
  del cols["scale_1"]
  path = _write(tmp_path / "missing.ply", cols)
  with pytest.raises(DatasetError, match=r"missing\.ply: missing vertex property scale_1"):
    load_ply(path)

  path = _write(tmp_path / "ascii.ply", _reference_columns(), text=True)
  with pytest.raises(DatasetError, match=r"ascii\.ply: ASCII PLY"):
    load_ply(path)

  good = tmp_path / "good.ply"
  write = _write(good, _reference_columns(n=4))
  (tmp_path / "cut.ply").write_bytes(write.read_bytes()[:-6])
  with pytest.raises(DatasetError, match=r"cut\.ply: truncated.*row 3.*property 'rot_2'"):
    load_ply(tmp_path / "cut.ply")

  cols = _reference_columns(rest=7)
  with pytest.raises(DatasetError, match=r"odd\.ply: 7 f_rest_\* properties"):
    load_ply(_write(tmp_path / "odd.ply", cols))
  cols = _reference_columns(rest=9)
  cols["f_rest_9"] = cols.pop("f_rest_4")
  with pytest.raises(DatasetError, match=r"gap\.ply: missing vertex property f_rest_4"):
    load_ply(_write(tmp_path / "gap.ply", cols))

  cols = _reference_columns(n=3)
  cols["opacity"][2] = np.nan
  with pytest.raises(DatasetError, match=r"nan\.ply: vertex property opacity is not finite "
                     "in row 2"):
    load_ply(_write(tmp_path / "nan.ply", cols))

  (tmp_path / "text.ply").write_text("hello\n")
  with pytest.raises(DatasetError, match=r"text\.ply: not a valid PLY header"):
    load_ply(tmp_path / "text.ply")
  with pytest.raises(FileNotFoundError, match="nothere.ply"):
    load_ply(tmp_path / "nothere.ply")


def test_ply_arrays_write_live_rows_only():
  model = _model(sh_degree=0)
  arrays = ply_arrays(model.params.mean, model.mask)
  assert len(arrays["x"]) == 5 and list(arrays) == REFERENCE
  assert all(not np.any(arrays[f"f_rest_{j}"]) for j in range(45))


def test_gaussians_round_trip_through_raw_parameters(tmp_path):
  gaussians = random_gaussians(30, sh_degree=2, seed=4)
  path = export_gaussians(tmp_path / "g.ply", gaussians)
  model = model_from_mean(jax.random.PRNGKey(0), load_ply(path), spec=SPEC, init_scales=SCALES)
  back = mean_gaussians(model)
  for name in ("means", "scales", "quats", "opacities", "sh"):
    np.testing.assert_allclose(np.asarray(getattr(back, name))[:30],
                               np.asarray(getattr(gaussians, name)), rtol=2e-6, atol=1e-7,
                               err_msg=name)


# ---------------------------------------------------------------------- rows and bytes


def _declare(path, old, new):
  """`path` with the header's element line `old` replaced by `new` (the data untouched)."""
  data = path.read_bytes()
  head, rest = data.split(b"end_header\n", 1)
  assert old.encode() in head
  path.write_bytes(head.replace(old.encode(), new.encode()) + b"end_header\n" + rest)
  return path


@pytest.mark.parametrize("byte_order", ["<", ">"])
@pytest.mark.parametrize("damage, message", [
    (lambda p: _declare(p, "element vertex 200", "element vertex 199"),
     r"rows\.ply: 56 bytes follow the last of the 199 vertex rows the header declares \(the size "
     r"of 1 row of 56 bytes\)"),
    (lambda p: p.write_bytes(p.read_bytes() + b"\0" * 1000),
     r"rows\.ply: 1000 bytes follow the last of the 200 vertex rows .*17.9 rows of 56 bytes"),
    (lambda p: p.write_bytes(p.read_bytes() + b"\n"), r"rows\.ply: 1 bytes follow"),
    (lambda p: _declare(p, "element vertex 200", "element vertex 20"),
     r"rows\.ply: 10080 bytes follow the last of the 20 vertex rows"),
    (lambda p: _declare(p, "element vertex 200", "element vertex 201"),
     r"rows\.ply: truncated: the header declares 201 vertex rows of 56 bytes, but the data "
     r"ends in row 200"),
], ids=["199 of 200 rows", "1000 trailing bytes", "a trailing newline", "20 of 200 rows",
        "201 of 200 rows"])
def test_the_declared_rows_must_fill_the_data_exactly(tmp_path, byte_order, damage, message):
  """Rows after the declared count were dropped without a word, trailing bytes accepted."""
  path = _write(tmp_path / "rows.ply", _reference_columns(n=200), byte_order=byte_order)
  assert len(load_ply(path)["means"]) == 200
  damage(path)
  with pytest.raises(DatasetError, match=message):
    load_ply(path)


def test_rows_after_an_element_of_lists_are_checked_after_reading(tmp_path):
  """Rows of list properties vary in size: the bytes left are known once plyfile read them."""
  table = np.empty(2, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
  table["x"] = [1.0, 2.0]
  faces = np.empty(1, dtype=[("vertex_indices", "O")])
  faces["vertex_indices"][0] = np.array([0, 1, 0], np.int32)
  path = tmp_path / "mesh.ply"
  plyfile.PlyData([plyfile.PlyElement.describe(table, "vertex"),
                   plyfile.PlyElement.describe(faces, "face")]).write(str(path))
  assert len(read_ply_data(path)["face"].data) == 1
  path.write_bytes(path.read_bytes() + b"\0" * 13)
  with pytest.raises(DatasetError, match=r"mesh\.ply: 13 bytes follow the last of the 1 face "
                                         "rows the header declares"):
    read_ply_data(path)


@pytest.mark.parametrize("change, message", [
    (lambda p: _declare(p, "element vertex 5", "element vertex 4"),
     r"text\.ply: the header declares 4 rows \(4 vertex\), but the data holds 5 lines .*its "
     "counts do not match the data"),
    (lambda p: p.write_bytes(p.read_bytes() + b"1 2 3 4 5 6 7 8 9 10 11 12 13 14\n"),
     r"declares 5 rows \(5 vertex\), but the data holds 6 lines"),
    (lambda p: _declare(p, "element vertex 5", "element vertex 100000000000"),
     r"declares 100000000000 rows .* holds 5 lines .*: truncated"),
], ids=["4 of 5 rows", "a line after the rows", "10^11 rows declared"])
def test_ascii_files_hold_one_line_per_declared_row(tmp_path, change, message):
  """Where ASCII is read (point clouds), the same rule: every row, and nothing after; a count
  of 10^11 is refused before plyfile allocates it. 3DGS models refuse ASCII at once."""
  path = _write(tmp_path / "text.ply", _reference_columns(n=5), text=True)
  assert len(read_ply_data(path, allow_ascii=True)["vertex"].data) == 5
  path.write_bytes(path.read_bytes() + b"\n\n")  # blank lines at the end are no rows
  assert len(read_ply_data(path, allow_ascii=True)["vertex"].data) == 5
  change(path)
  with pytest.raises(DatasetError, match=message):
    read_ply_data(path, allow_ascii=True)
  with pytest.raises(DatasetError, match=r"text\.ply: ASCII PLY"):
    load_ply(path)
