"""Tests of mfsample.export_ply: the standard 3DGS layout, round trip."""

import jax
import numpy as np

from mfsample.export_ply import export_ply, read_ply
from mfsample.model import GROUPS, SamplerSpec, init_model


def _model(sh_degree):
  spec = SamplerSpec(kind="lowrank", rank=2, groups=("means",), bounds=(("means", 1.0),))
  pts = np.random.default_rng(0).uniform(-1, 1, (5, 3))
  model = init_model(jax.random.PRNGKey(0), pts, spec=spec, sh_degree=sh_degree,
                     init_scales={g: 1e-3 for g in GROUPS}, capacity=8)
  mean = dict(model.params.mean)
  if "sh_rest" in mean:  # distinct values reveal the channel-major ordering of f_rest
    mean["sh_rest"] = mean["sh_rest"].at[:].set(
        np.arange(np.prod(mean["sh_rest"].shape[1:]), dtype=np.float32).reshape(
            mean["sh_rest"].shape[1:]))
  return model.replace(params=model.params._replace(mean=mean))


def test_layout_and_round_trip(tmp_path):
  model = _model(sh_degree=3)
  path = str(tmp_path / "model.ply")
  export_ply(path, model)
  with open(path, "rb") as f:
    header = f.read(2000).split(b"end_header")[0].decode()
  names = [line.split()[-1] for line in header.splitlines() if line.startswith("property")]
  expected = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
              + [f"f_rest_{i}" for i in range(45)] + ["opacity"]
              + [f"scale_{i}" for i in range(3)] + [f"rot_{i}" for i in range(4)])
  assert names == expected
  assert "format binary_little_endian 1.0" in header and "element vertex 5" in header
  data = read_ply(path)
  mean = {g: np.asarray(v)[:5] for g, v in model.params.mean.items()}
  np.testing.assert_array_equal(np.stack([data["x"], data["y"], data["z"]], 1), mean["means"])
  np.testing.assert_array_equal(data["opacity"], mean["opacity_logits"])  # raw logits
  np.testing.assert_array_equal(data["scale_0"], mean["log_scales"][:, 0])  # raw log-scales
  np.testing.assert_array_equal(data["rot_0"], mean["quats"][:, 0])
  # f_rest is channel-major: all 15 red coefficients, then green, then blue.
  rest = np.stack([data[f"f_rest_{i}"] for i in range(45)], 1).reshape(5, 3, 15)
  np.testing.assert_array_equal(rest, np.transpose(mean["sh_rest"], (0, 2, 1)))


def test_degree_0_has_no_f_rest(tmp_path):
  path = str(tmp_path / "model.ply")
  export_ply(path, _model(sh_degree=0))
  data = read_ply(path)
  assert not any(k.startswith("f_rest") for k in data) and len(data["x"]) == 5
