"""Tests of mfsample.next_views: the uncertainty job, on a synthetic scene and on a COLMAP
capture with a .ply trained by the job itself."""

import json
import os
import pathlib

import jax.numpy as jnp
import numpy as np
import pytest
from absl import flags
from ml_collections import config_flags

from configs import uncertainty as uncertainty_configs
from mfsample.config_checks import ConfigError
from mfsample.next_views import run_uncertainty, sphere_candidates, top_k
from mfsample.next_views.candidates import capture_up

ROOT = pathlib.Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def joint_run(tmp_path_factory):
  workdir = str(tmp_path_factory.mktemp("joint"))
  return workdir, run_uncertainty(uncertainty_configs.get_config("tiny"), workdir)


@pytest.mark.slow
def test_tiny_job_trains_maps_and_proposes(joint_run):
  workdir, results = joint_run
  assert results["kind"] == "joint" and results["steps"] == 40
  assert results["num_train_views"] == 6 and results["next_views"]["num_candidates"] == 6
  for name in ("config.json", "train_log.json", "point_cloud.ply", "next_views.json",
               "next_views.png", "results.json", "test/metrics.json", "test/uncertainty.npy",
               "test/test_000_uncertainty.png"):
    assert os.path.exists(os.path.join(workdir, name)), name
  with open(os.path.join(workdir, "next_views.json")) as f:
    record = json.load(f)
  u = np.asarray(record["u"])
  assert np.all(u > 0) and [t["index"] for t in record["top_k"]] == list(np.argsort(-u)[:2])
  assert record["names"][record["top_k"][0]["index"]] == results["top_k"][0]["name"]
  assert record["top_k"][0]["error"] > 0 and -1 <= results["next_views"]["rho_u_error"] <= 1
  assert results["test"]["mean_u"] > 0 and results["test"]["psnr"] > 10


@pytest.mark.slow
def test_the_viewer_reads_the_job_as_it_wrote_it(joint_run):
  """The viewer (`mfsample.viewer`) rebuilds the candidates from config.json as the job split
  them, reads the model from the checkpoint and finds the job's U of the first proposal."""
  from mfsample.viewer import open_run
  from mfsample.viewer.models import Renderer, samples

  workdir, _ = joint_run
  run = open_run(workdir)
  run.load_inputs()
  assert run.inputs_error == ""
  (step,) = run.steps()
  with open(os.path.join(workdir, "next_views.json")) as f:
    record = json.load(f)
  assert step.candidates[1] == record["names"] and len(step.train[1]) == 6
  np.testing.assert_allclose(step.scores, record["u"])
  for proposal, top in zip(step.proposals, record["top_k"], strict=True):
    np.testing.assert_allclose(step.candidates[0][proposal.index].world_to_camera,
                               top["world_to_camera"], atol=1e-6)
  model = run.model(step)
  with open(os.path.join(workdir, "results.json")) as f:
    assert model.num_live == json.load(f)["live_gaussians"]
  num, seed = run.u_samples()
  _, _, u = Renderer().colour(model, step.proposals[0].camera, samples(model, num, seed),
                              run.background())
  assert u == pytest.approx(record["top_k"][0]["u"], rel=1e-4)
  truth = run.ground_truth(step, "candidates", step.proposals[0].index)
  assert truth.shape == (32, 32, 3)


@pytest.mark.slow
def test_tiny_job_resumes_and_refuses_another_config(joint_run):
  workdir, results = joint_run
  config = uncertainty_configs.get_config("tiny")
  assert run_uncertainty(config, workdir) == results  # finished: read back, nothing redone
  os.remove(os.path.join(workdir, "results.json"))  # killed after training: resumes there
  again = run_uncertainty(config, workdir)
  assert again["steps"] == 40 and again["top_k"] == results["top_k"]
  config.next_views.k = 3
  config.train.progress = True  # presentation only: not a difference
  with pytest.raises(ValueError, match=r"different config \(differences: next_views.k\)"):
    run_uncertainty(config, workdir)


@pytest.mark.slow
def test_colmap_capture_and_a_ply_get_posthoc_uncertainty(joint_run, tmp_path):
  """A COLMAP capture of the synthetic scene and the .ply the joint run wrote: B_hat is fitted
  to the frozen model, the candidates are new poses on a sphere."""
  from mfsample.data import PointCloud, export_colmap
  from mfsample.data.ply import load_ply
  from mfsample.train import data as data_lib

  config = uncertainty_configs.get_config("tiny")
  dataset = data_lib.load_dataset(config.data)
  both = dataset.train.subset(range(12)).replace(names=())
  xyz = np.asarray(data_lib.synthetic_gaussians(config.data.synthetic.num_gaussians, 0).means)
  export_colmap(tmp_path / "capture", both, PointCloud(xyz, np.full_like(xyz, 0.5)))
  ply = os.path.join(joint_run[0], "point_cloud.ply")
  config.data.kind = "colmap"
  config.data.path = str(tmp_path / "capture")
  config.data.holdout_every = 4
  config.posthoc.ply = ply
  config.posthoc.steps = 6
  config.views.train_every = 1
  config.next_views.candidates = "sphere"
  workdir = str(tmp_path / "posthoc")
  results = run_uncertainty(config, workdir)
  assert results["kind"] == "posthoc" and results["steps"] == 6
  assert results["num_train_views"] == 9 and results["num_test_views"] == 3
  assert results["next_views"]["num_candidates"] == 6
  assert results["next_views"]["rho_u_error"] is None  # new poses have no images
  assert not os.path.exists(os.path.join(workdir, "point_cloud.ply"))  # the user's own
  assert os.path.exists(os.path.join(workdir, "next_views.png"))
  assert results["test"]["mean_u"] > 0
  stored = load_ply(ply)
  assert results["live_gaussians"] == len(stored["means"])


def test_config_is_checked_before_anything_is_written(tmp_path):
  for field, value, message in [
      ("next_views.samples", 1, "config.next_views.samples = 1"),
      ("next_views.candidates", "grid", "config.next_views.candidates = 'grid'"),
      ("sampler.kind", "deterministic", "config.sampler.kind = 'deterministic'"),
      ("views.train_every", 1, "config.views.train_every = 1 trains on every view"),
      ("data.kind", "nerf", "config.data.kind = 'nerf'")]:
    config = uncertainty_configs.get_config("tiny")
    node, leaf = config, field.split(".")
    for part in leaf[:-1]:
      node = node[part]
    node[leaf[-1]] = value
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
      run_uncertainty(config, str(tmp_path / "w"))
  config = uncertainty_configs.get_config("tiny")
  config.posthoc.ply = str(tmp_path / "missing.ply")
  with pytest.raises(FileNotFoundError, match="config.posthoc.ply"):
    run_uncertainty(config, str(tmp_path / "w"))
  assert not os.path.exists(tmp_path / "w")


@pytest.mark.parametrize("variant", ["", "tiny", "colmap,posthoc"])
def test_variants_load_from_the_command_line(variant):
  spec = f"uncertainty.py:{variant}" if variant else "uncertainty.py"
  argv = ["prog", f"--config={ROOT / 'configs' / spec}", "--config.next_views.k=7",
          "--config.posthoc.ply=model.ply"]
  fv = flags.FlagValues()
  config_flags.DEFINE_config_file("config", None, "", flag_values=fv, lock_config=True,
                                  sys_argv=argv)
  fv(argv)
  assert fv.config.next_views.k == 7 and fv.config.posthoc.ply == "model.ply"
  assert fv.config.data.kind == {"": "scene", "tiny": "synthetic", "colmap,posthoc": "colmap"}[
      variant]
  with pytest.raises(ValueError, match="unknown variant"):
    uncertainty_configs.get_config("huge")


def test_sphere_candidates_follow_the_capture():
  from mfsample.camera import Camera

  up = np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0)  # a capture whose "up" is not +z
  center = np.array([1.0, 2.0, 3.0])
  side = np.cross(up, [1.0, 0.0, 0.0])
  eyes = center + 2.0 * np.stack([side, -side, up, np.cross(up, side)])
  train = Camera.look_at(jnp.asarray(eyes, jnp.float32), jnp.asarray(
      np.broadcast_to(center, eyes.shape), jnp.float32), jnp.asarray(up, jnp.float32), 0.9,
      20, 16)
  np.testing.assert_allclose(capture_up(train[:2]), up, atol=1e-6)
  cams = sphere_candidates(train, center, 10)
  centers = np.asarray(cams.center, np.float64)
  np.testing.assert_allclose(np.linalg.norm(centers - center, axis=1), 2.0, rtol=1e-5)
  _, depth = cams.project(jnp.asarray(center[None], jnp.float32)[None].repeat(10, 0))
  np.testing.assert_allclose(np.asarray(depth)[:, 0], 2.0, rtol=1e-5)  # looking at it
  assert (cams.width, cams.height) == (20, 16) and float(cams.fx[3]) == float(train.fx[0])
  np.testing.assert_array_equal(top_k([0.1, 0.5, 0.5, 0.2], 3), [1, 2, 3])


def test_a_workdir_whose_call_failed_early_is_taken_over(tmp_path):
  config = uncertainty_configs.get_config("tiny")
  config.data.kind = "colmap"
  config.data.path = str(tmp_path / "typo")
  workdir = str(tmp_path / "w")
  with pytest.raises(FileNotFoundError, match="typo"):
    run_uncertainty(config, workdir)
  config.data.path = str(tmp_path / "still_missing")  # a new config, nothing computed yet
  with pytest.raises(FileNotFoundError, match="still_missing"):
    run_uncertainty(config, workdir)
