"""The device check (`benchmarks/gpu_check.py`) on the CPU at a tiny size.

Its parts are tested in this process (a render part, the CPU reference, their comparison)
and its runner with stand-in child processes (results kept as they come, a failing part
isolated, the time budget). Timings at these sizes mean nothing.
"""

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from bench_testlib import import_script

from mfsample import _workloads

gpu_check, DEFAULTS = import_script("gpu_check")
# gsplat's garden test data: $MFSAMPLE_GARDEN, else the data folder beside the checkout.
GARDEN = str(Path(os.environ.get("MFSAMPLE_GARDEN") or Path(__file__).parents[2] / ".."
                  / "shared" / "data" / "real" / "garden_points" / "test_garden.npz").resolve())


def test_part_names_parse_into_workload_compositor_and_settings():
  assert gpu_check.parse_part("garden/pallas:chunk_size=16:skip_unused_steps=False") == (
      "garden", "pallas", {"chunk_size": 16, "skip_unused_steps": False})
  assert gpu_check.parse_part("step/jnp@256") == ("step", "jnp", {"chunks_per_step": 256})
  assert gpu_check.parse_part("50k400/jnp:searchsorted_method=sort") == (
      "50k400", "jnp", {"searchsorted_method": "sort"})
  for bad in ("lego/jnp", "garden", "garden/jnp:chunk_size"):
    with pytest.raises(ValueError, match="part"):
      gpu_check.parse_part(bad)
  for part in DEFAULTS["parts"]:  # the default parts all parse, and pass as a --parts list
    assert "," not in part
    if part not in (gpu_check.REFERENCE, gpu_check.OVERHEAD):
      gpu_check.parse_part(part)


def test_step_parts_call_train_step_with_the_renderer_share():
  command = gpu_check.step_command("step/pallas@64", data="lego", size=400, points=100_000,
                                   steps=10)
  assert command[1].endswith(os.path.join("benchmarks", "train_step.py"))
  for arg in ("--child=rank2@64", "--compositor=pallas", "--size=400", "--points=100000",
              "--samples=1", "--steps=10", "--render_share", "--fit_start_budget"):
    assert arg in command
  with pytest.raises(ValueError, match="only @C"):
    gpu_check.step_command("step/jnp:chunk_size=8", data="", size=8, points=8, steps=1)


@pytest.mark.skipif(not os.path.exists(GARDEN), reason="gsplat's garden data not present")
def test_garden_workload_is_gsplats_crop_with_its_random_attributes():
  gaussians, camera, source = _workloads.garden(GARDEN)
  assert source == GARDEN and gaussians.num_gaussians == _workloads.GARDEN_POINTS
  assert (camera.width, camera.height) == _workloads.GARDEN_SIZE
  assert float(camera.fx) == pytest.approx(_workloads.GARDEN_FOCAL, abs=0.1)
  scales, opacities = np.asarray(gaussians.scales), np.asarray(gaussians.opacities)
  assert 1e-4 <= scales.min() and scales.max() <= 0.02
  assert 0.0 <= opacities.min() and opacities.max() <= 1.0
  np.testing.assert_allclose(np.linalg.norm(gaussians.quats, axis=-1), 1.0, rtol=1e-5)
  assert np.abs(np.asarray(gaussians.means)).max() <= _workloads.GARDEN_CROP
  assert gaussians.sh_degree == 3
  small = _workloads.garden(GARDEN, shrink=8)
  assert small.gaussians.num_gaussians == -(-_workloads.GARDEN_POINTS // 64)
  assert (small.camera.width, small.camera.height) == (81, 53)


def test_garden_stand_in_has_the_same_size_and_a_bad_file_is_named(tmp_path):
  gaussians, camera, source = _workloads.garden(None)
  assert "stand-in" in source and gaussians.num_gaussians == _workloads.GARDEN_POINTS
  assert (camera.width, camera.height) == _workloads.GARDEN_SIZE
  assert float(camera.fx) == pytest.approx(_workloads.GARDEN_FOCAL, rel=1e-4)
  bad = tmp_path / "garden.npz"
  np.savez(bad, means3d=np.zeros((3, 3)))
  with pytest.raises(ValueError, match="garden.npz"):
    _workloads.garden(str(bad))


@pytest.mark.slow
def test_a_render_part_measures_and_matches_the_cpu_reference(tmp_path):
  part = "50k400/jnp"  # the reference's settings: the compilations are shared
  result = gpu_check.run_render(part, garden="", tiny=True, repeats=2, scratch=str(tmp_path))
  assert result["workload"] == "50k400" and result["compositor"] == "jnp"
  assert result["num_gaussians"] == 500 and result["image"] == [48, 48]
  assert result["intersections"] > 0 and not result["overflow"]
  # The budget training would grow to: the next power of two of the padded count.
  assert result["budget"] >= result["padded_intersections"] > result["budget"] // 2
  for key in ("forward_ms", "forward_backward_ms", "forward_backward_pipelined_ms"):
    assert result[key] > 0
  assert result["peak_rss_mb"] > 0 and result["xla_backward_mb"] > 0
  floor = gpu_check.run_overhead(garden="", tiny=True, repeats=2)
  assert 0 < floor["call_ms"] and 0 < floor["call_pipelined_ms"]
  reference = gpu_check.run_reference(["50k400"], garden="", tiny=True, scratch=str(tmp_path))
  assert reference["workloads"]["50k400"]["intersections"] == result["intersections"]
  got = tmp_path / gpu_check._file_name(part)
  want = tmp_path / gpu_check._file_name("reference_50k400")
  same = gpu_check.compare_outputs(got, want)
  # The same program on the same device: equal.
  assert same["image_max_abs_diff"] == 0.0 and same["grad_rel_l2_diff"] == 0.0
  leaves = set(same["grads"])
  assert {"[0].means", "[0].scales", "[0].quats", "[0].opacities", "[0].sh",
          "[1].world_to_camera"} <= leaves
  # A fault in one gradient leaf shows in the figures.
  with np.load(got) as data:
    arrays = dict(data)
  arrays["grad[0].opacities"] = arrays["grad[0].opacities"] * 1.01
  np.savez(got, **arrays)
  assert gpu_check.compare_outputs(got, want)["grad_rel_l2_diff"] == pytest.approx(0.01,
                                                                                    rel=1e-2)


def _stand_in(result=None, fail=None, sleep=0.0):
  """A child command printing `result` (or failing with `fail`) after `sleep` seconds."""
  code = f"import json, sys, time; time.sleep({sleep})\n"
  code += f"sys.exit({fail!r})" if fail else f"print('RESULT ' + json.dumps({result!r}))"
  return [sys.executable, "-c", code], False


def _render_result(workload):
  return {"workload": workload, "num_gaussians": 5, "image": [4, 4], "intersections": 7,
          "budget": 8, "forward_ms": 1.0, "forward_backward_ms": 2.0,
          "forward_backward_pipelined_ms": 1.5, "device_peak_mb": None,
          "xla_backward_mb": 1.0, "machine": {"device_kind": "stand-in", "jax": "0"}}


def test_runner_keeps_results_isolates_failures_and_compares(tmp_path):
  out, scratch = tmp_path / "out", tmp_path / "scratch"
  scratch.mkdir()
  rgb = np.zeros((4, 4, 3), np.float32)
  for name, shift in (("garden_jnp", 0.0), ("reference_garden", 0.25)):
    np.savez(scratch / f"{name}.npz", rgb=rgb + shift, alpha=rgb[..., 0],
             **{"grad[0].means": np.ones(3) + shift})
  commands = {
      "garden/jnp": _stand_in(_render_result("garden")),
      "garden/pallas": _stand_in(fail="a kernel fault"),
      "reference": _stand_in({"workloads": {}}),
      "overhead": _stand_in({"call_ms": 0.05, "call_pipelined_ms": 0.01}),
      "step/jnp": _stand_in({"ms_median": 3.0, "render_forward_backward_ms": 1.0,
                             "outside_renderer_share": 2 / 3, "live": 5, "resolution": 4,
                             "device_peak_mb": None, "scene": "synthetic"}),
  }
  record = gpu_check.run_all(str(out), list(commands), 60.0, str(scratch), commands.get)
  status = {p["part"]: p["status"] for p in record["parts"]}
  assert status == {"garden/jnp": "ok", "garden/pallas": "failed", "reference": "ok",
                    "overhead": "ok", "step/jnp": "ok"}
  assert record["status"] == "complete" and record["machine"]["device_kind"] == "stand-in"
  parts = {p["part"]: p for p in record["parts"]}
  assert "a kernel fault" in parts["garden/pallas"]["error"]
  assert parts["garden/jnp"]["image_max_abs_diff"] == pytest.approx(0.25)
  assert parts["garden/jnp"]["grad_rel_l2_diff"] == pytest.approx(0.2)
  saved = json.loads((out / "gpu_check.json").read_text())
  assert saved["parts"] == json.loads(json.dumps(record["parts"]))
  table = (out / "gpu_check.md").read_text()
  assert "stand-in" in table and "| garden/jnp | 5 | 4x4 | 7 | 8 | 1.00 | 2.00 | 1.50 |" in table
  assert "| step/jnp | synthetic | 5 | 4^2 | 3.0 | 1.0 | 67% |" in table
  assert "| garden/pallas | failed |" in table and "kernel fault" in table
  assert "Timing floor (overhead): 0.050 ms a call blocked on, 0.010 ms" in table


def test_runner_stops_at_the_time_budget_and_skips_what_cannot_fit(tmp_path, monkeypatch):
  monkeypatch.setattr(gpu_check, "MIN_PART_SECONDS", 0.5)
  commands = {"garden/jnp": _stand_in(_render_result("garden"), sleep=30.0),
              "50k400/jnp": _stand_in(_render_result("50k400"))}
  record = gpu_check.run_all(str(tmp_path), list(commands), 2.0, str(tmp_path), commands.get)
  first, second = record["parts"]
  assert first["status"] == "stopped at the time budget" and first["seconds"] < 10
  assert second["status"] == "skipped" and "time budget" in second["error"]
  assert json.loads((tmp_path / "gpu_check.json").read_text())["status"] == "complete"
  none = gpu_check.run_all(str(tmp_path), ["garden/jnp"], 0.0, str(tmp_path), commands.get)
  assert [p["status"] for p in none["parts"]] == ["skipped"]
