"""Tests of mfsample.your_data: the uncertainty job, on a synthetic scene and on a COLMAP
capture with a .ply trained by the job itself."""

import json
import os
import pathlib

import jax.numpy as jnp
import numpy as np
import pytest
from absl import flags
from ml_collections import config_flags

from configs import next_views as next_views_configs
from mfsample.config_blocks import data_spec
from mfsample.config_checks import ConfigError
from mfsample.selection import top_k
from mfsample.your_data import run_next_views, sphere_candidates
from mfsample.your_data.candidates import capture_up

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def joint_run(tmp_path_factory):
  workdir = str(tmp_path_factory.mktemp("joint"))
  return workdir, run_next_views(next_views_configs.get_config("tiny"), workdir)


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
  from mfsample.viewer.models import render_u, samples

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
  _, u, _ = render_u(model, step.proposals[0].camera, samples(model, num, seed),
                     run.background())
  assert u == pytest.approx(record["top_k"][0]["u"], rel=1e-4)
  truth = run.ground_truth(step, "candidates", step.proposals[0].index)
  assert truth.shape == (32, 32, 3)


@pytest.mark.slow
def test_tiny_job_resumes_and_refuses_another_config(joint_run):
  workdir, results = joint_run
  config = next_views_configs.get_config("tiny")
  assert run_next_views(config, workdir) == results  # finished: read back, nothing redone
  os.remove(os.path.join(workdir, "results.json"))  # killed after training: resumes there
  again = run_next_views(config, workdir)
  assert again["steps"] == 40 and again["top_k"] == results["top_k"]
  config.next_views.k = 3
  config.train.progress = True  # presentation only: not a difference
  with pytest.raises(ValueError, match=r"different config \(differences: next_views.k\)"):
    run_next_views(config, workdir)


@pytest.mark.slow
def test_colmap_capture_and_a_ply_get_posthoc_uncertainty(joint_run, tmp_path):
  """A COLMAP capture of the synthetic scene and the .ply the joint run wrote: B_hat is fitted
  to the frozen model, the candidates are new poses on a sphere."""
  from mfsample.data import PointCloud, export_colmap, synthetic
  from mfsample.data import datasets as data_lib
  from mfsample.data.ply import load_ply

  config = next_views_configs.get_config("tiny")
  dataset = data_lib.load_dataset(data_spec(config.data))
  both = dataset.train.subset(range(12)).replace(names=())
  xyz = np.asarray(synthetic.synthetic_gaussians(config.data.synthetic.num_gaussians, 0).means)
  export_colmap(tmp_path / "capture", both, PointCloud(xyz, np.full_like(xyz, 0.5)))
  ply = os.path.join(joint_run[0], "point_cloud.ply")
  config.data.kind = "colmap"
  config.data.path = str(tmp_path / "capture")
  config.data.holdout_every = 4
  config.posthoc.ply = ply
  config.posthoc.steps = 6
  config.views.train_every = 1
  config.next_views.candidates = "sphere"
  config.posthoc.min_psnr = 99.0  # no model reaches it: the warning is given
  workdir = str(tmp_path / "posthoc")
  with pytest.warns(UserWarning, match=r"renders the test views at [\d.]+ dB PSNR, below "
                    r"posthoc.min_psnr = 99: it does not reproduce this capture"):
    results = run_next_views(config, workdir)
  assert results["kind"] == "posthoc" and results["steps"] == 6
  assert len(results["warnings"]) == 1 and results["test"]["psnr"] < 99
  from mfsample.your_data.runner import report

  assert "  warning: the model of posthoc.ply" in report(results, workdir)
  assert joint_run[1]["warnings"] == []  # (a trained field is never warned about)
  assert results["num_train_views"] == 9 and results["num_test_views"] == 3
  assert results["next_views"]["num_candidates"] == 6
  assert results["next_views"]["rho_u_error"] is None  # new poses have no images
  assert not os.path.exists(os.path.join(workdir, "point_cloud.ply"))  # the user's own
  assert os.path.exists(os.path.join(workdir, "next_views.png"))
  assert results["test"]["mean_u"] > 0
  stored = load_ply(ply)
  assert results["live_gaussians"] == len(stored["means"])


@pytest.mark.slow
def test_results_whose_files_are_damaged_are_computed_again(joint_run, tmp_path):
  """A finished workdir (copied, times kept) whose next_views.json is damaged and whose
  next_views/ is gone: both are computed again from the checkpoints, bit for bit."""
  import shutil

  workdir = tmp_path / "copy"
  shutil.copytree(joint_run[0], workdir)
  config = next_views_configs.get_config("tiny")
  finished = json.loads((workdir / "results.json").read_text())
  assert set(finished.pop("_files")) >= {"next_views.json", "train_log.json",
                                         os.path.join("next_views", "cameras.json")}
  assert run_next_views(config, str(workdir)) == finished  # intact: read back
  record = (workdir / "next_views.json").read_bytes()
  exported = {p.relative_to(workdir): p.read_bytes() for p in (workdir / "next_views").rglob("*")
              if p.is_file()}
  (workdir / "next_views.json").write_bytes(record[: len(record) // 2])
  shutil.rmtree(workdir / "next_views")
  with pytest.warns(UserWarning, match=r"results.json points to files that are no longer what "
                    r"it wrote \(.*next_views"):
    again = run_next_views(config, str(workdir))
  assert again["top_k"] == finished["top_k"] and again["test"] == finished["test"]
  assert (workdir / "next_views.json").read_bytes() == record
  assert {p.relative_to(workdir): p.read_bytes() for p in (workdir / "next_views").rglob("*")
          if p.is_file()} == exported
  assert run_next_views(config, str(workdir)) == again  # and read back again


@pytest.mark.slow
def test_a_posthoc_model_replaced_at_its_path_stops_the_rerun_or_is_recomputed(joint_run,
                                                                              tmp_path):
  """The 3DGS workflow: a model retrained to the same path. The finished workdir of the old
  model stops, naming the file; with data.inputs_changed = "recompute" the results are those
  of the new model."""
  import shutil

  from mfsample.data.ply import load_ply, write_gaussians_ply
  from mfsample.workdir import InputsChangedError

  ply = tmp_path / "point_cloud.ply"
  shutil.copy(os.path.join(joint_run[0], "point_cloud.ply"), ply)
  config = next_views_configs.get_config("tiny")
  config.posthoc.ply = str(ply)
  config.posthoc.steps = 6
  config.views.train_every = 1
  config.next_views.candidates = "sphere"
  workdir = str(tmp_path / "w")
  first = run_next_views(config, workdir)
  with open(os.path.join(workdir, "inputs.json")) as f:
    assert list(json.load(f)["files"]) == [str(ply)]  # (synthetic data: no files)
  retrained = load_ply(ply)
  retrained["opacity_logits"] = retrained["opacity_logits"] - 1.0  # same size, other model
  write_gaussians_ply(ply, retrained)
  results = os.path.join(workdir, "results.json")
  before = os.stat(results).st_mtime_ns
  with pytest.raises(InputsChangedError, match=rf"{ply}: modified .*, sha256 \w+ -> \w+\. "
                     r"Restore them, .*--config.data.inputs_changed=recompute"):
    run_next_views(config, workdir)
  assert os.stat(results).st_mtime_ns == before  # nothing computed, nothing written
  config.data.inputs_changed = "recompute"
  with pytest.warns(UserWarning, match=rf"{ply}: .*computing them again"):
    second = run_next_views(config, workdir)
  assert second["steps"] == 6 and second["test"]["mean_u"] != first["test"]["mean_u"]
  config.data.inputs_changed = "stop"  # free: the same workdir, now of the new model
  assert run_next_views(config, workdir) == second


@pytest.mark.slow
def test_a_finished_workdir_on_a_read_only_mount_is_read_back(joint_run, tmp_path):
  """`experiments/next_views.py` on a read-only copy: a finished workdir prints its report
  (exit 0, no lock file); one with results to compute stops with one line naming it."""
  import shutil
  import sys

  from readonly_testlib import run_read_only

  mount = tmp_path / "mount"
  shutil.copytree(joint_run[0], mount / "done")
  shutil.copytree(joint_run[0], mount / "unfinished")
  os.remove(mount / "unfinished" / "results.json")
  command = [sys.executable, str(ROOT / "experiments" / "next_views.py"),
             f"--config={ROOT / 'configs' / 'next_views.py'}:tiny"]
  done = run_read_only(mount, command + [f"--workdir={mount / 'done'}"], cwd=str(tmp_path))
  assert done.returncode == 0, done.stderr
  assert "next view 1:" in done.stdout and "Traceback" not in done.stderr
  unfinished = run_read_only(mount, command + [f"--workdir={mount / 'unfinished'}"],
                             cwd=str(tmp_path))
  assert unfinished.returncode == 2
  assert unfinished.stderr.strip().splitlines()[-1] == (
      f"next views: WorkdirReadOnlyError: {mount / 'unfinished'} is read-only, and this next "
      "views call has results to compute and write (config.json): make it writable, or use "
      "another --workdir (--verbose shows the traceback)")
  assert "Traceback" not in unfinished.stderr
  viewer = run_read_only(mount, [sys.executable, "-c", "import sys\n"
                                 "from mfsample.viewer import open_run\n"
                                 "print(len(open_run(sys.argv[1]).steps()))",
                                 str(mount / "done")], cwd=str(ROOT))
  assert viewer.returncode == 0 and viewer.stdout.strip() == "1", viewer.stderr
  assert not list(mount.rglob(".lock"))


def test_config_is_checked_before_anything_is_written(tmp_path):
  for field, value, message in [
      ("next_views.samples", 1, "config.next_views.samples = 1"),
      ("next_views.candidates", "grid", "config.next_views.candidates = 'grid'"),
      ("sampler.kind", "deterministic", "config.sampler.kind = 'deterministic'"),
      ("views.train_every", 1, "config.views.train_every = 1 trains on every view"),
      ("data.kind", "nerf", "config.data.kind = 'nerf'")]:
    config = next_views_configs.get_config("tiny")
    node, leaf = config, field.split(".")
    for part in leaf[:-1]:
      node = node[part]
    node[leaf[-1]] = value
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
      run_next_views(config, str(tmp_path / "w"))
  config = next_views_configs.get_config("tiny")
  config.posthoc.ply = str(tmp_path / "missing.ply")
  with pytest.raises(FileNotFoundError, match="config.posthoc.ply"):
    run_next_views(config, str(tmp_path / "w"))
  assert not os.path.exists(tmp_path / "w")


@pytest.mark.parametrize("fields, message", [
    ({"data.num_train": 1}, r"config.data.num_train = 1 with config.views.train_every = 2 "
     r"leaves no unused candidate view"),
    ({"data.num_train": 1, "views.train_every": 7}, r"config.data.num_train = 1 with "
     r"config.views.train_every = 7 leaves no unused"),
    ({"next_views.score_downscale": 64}, r"config.next_views.score_downscale = 64: the "
     r"candidates are 32 x 32 pixels \(config.data.width x height\).* must be <= 32"),
    ({"next_views.score_downscale": 33, "next_views.candidates": "sphere"},
     r"score_downscale = 33"),
])
def test_what_the_data_forbid_is_refused_at_validation(fields, message, tmp_path):
  """Checks that depend on the config and the data's shapes alone fail before training."""
  config = next_views_configs.get_config("tiny")
  for field, value in fields.items():
    block, leaf = field.split(".")
    config[block][leaf] = value
  with pytest.raises(ConfigError, match=message):
    run_next_views(config, str(tmp_path / "w"))
  assert not os.path.exists(tmp_path / "w")


@pytest.mark.slow
def test_what_a_capture_forbids_is_refused_once_it_is_loaded_before_training(tmp_path):
  """A capture's views are known once it is read: the same rules, before anything trains or
  is written."""
  from mfsample import testing
  from mfsample.data import PointCloud, export_colmap

  views, truth = testing.synthetic_views(3, size=32)
  xyz = np.asarray(truth.means)
  export_colmap(tmp_path / "capture", views.replace(names=()),
                PointCloud(xyz, np.full_like(xyz, 0.5)))
  config = next_views_configs.get_config("tiny")
  config.data.kind = "colmap"
  config.data.path = str(tmp_path / "capture")
  config.data.holdout_every = 3  # view 0 tests, views 1 and 2 train
  config.next_views.score_downscale = 40  # (width and height are not the capture's fields)
  with pytest.raises(ConfigError, match=r"score_downscale = 40: the candidates are 32 x 32 "
                     r"pixels \(the images of the dataset at .*capture\)"):
    run_next_views(config, str(tmp_path / "w"))
  assert not os.path.exists(tmp_path / "w")


@pytest.mark.parametrize("variant", ["", "tiny", "colmap,posthoc"])
def test_variants_load_from_the_command_line(variant):
  spec = f"next_views.py:{variant}" if variant else "next_views.py"
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
    next_views_configs.get_config("huge")


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
  config = next_views_configs.get_config("tiny")
  config.data.kind = "colmap"
  config.data.path = str(tmp_path / "typo")
  workdir = str(tmp_path / "w")
  with pytest.raises(FileNotFoundError, match="typo"):
    run_next_views(config, workdir)
  config.data.path = str(tmp_path / "still_missing")  # a new config, nothing computed yet
  with pytest.raises(FileNotFoundError, match="still_missing"):
    run_next_views(config, workdir)


@pytest.mark.parametrize("num_candidates", [1, 3, 200])
def test_figure_lays_out_one_to_hundreds_of_candidates_without_overlapping_text(
    num_candidates, tmp_path):
  """Every text of the figure (titles, rank numbers, legends, colour bar ticks and labels)
  has a box of its own, with one candidate (the centres on a line) as with 200."""
  import itertools

  import matplotlib.pyplot as plt
  from matplotlib.text import Text

  from mfsample.your_data.figure import build_figure, next_views_figure

  rng = np.random.default_rng(num_candidates)
  d = rng.normal(size=(num_candidates, 3))
  centers = 3.0 * d / np.linalg.norm(d, axis=1, keepdims=True)
  u = rng.uniform(size=num_candidates)
  top = top_k(u, 5)
  k = len(top)
  kwargs = dict(train_centers=rng.normal(size=(1 if num_candidates == 1 else 4, 3)),
                candidate_centers=centers, u=u, top=top,
                top_renders=rng.uniform(size=(k, 12, 16, 3)),
                top_maps=rng.uniform(size=(k, 12, 16)),
                top_images=rng.uniform(size=(k, 12, 16, 3)) if num_candidates < 10 else None,
                test_renders=rng.uniform(size=(2, 12, 16, 3)),
                test_maps=rng.uniform(size=(2, 12, 16)), title="scene: 1 training view",
                top_names=[f"frame_{i:05d}" for i in top], test_names=["a", "b"])
  fig = build_figure(**kwargs)
  renderer = fig.canvas.get_renderer()
  texts = [(t.get_text(), t.get_window_extent(renderer)) for t in fig.findobj(Text)
           if t.get_visible() and t.get_text().strip()]
  assert {str(r) for r in range(1, k + 1)} <= {t for t, _ in texts}  # every rank numbered
  assert sum(t.startswith("U = ") for t, _ in texts) == k + 2  # every U map has its U
  overlaps = [(a, b) for (a, box_a), (b, box_b) in itertools.combinations(texts, 2)
              if box_a.overlaps(box_b)]
  assert not overlaps
  plt.close(fig)
  if num_candidates == 1:  # the file itself, once
    path = next_views_figure(tmp_path / "next_views.png", **kwargs)
    assert path.stat().st_size > 10_000 and not list(tmp_path.glob("*.tmp.*"))


@pytest.mark.slow
def test_a_three_view_nerfstudio_capture_end_to_end(tmp_path):
  """A capture of 3 views (as the 3 bonsai frames): one test view, one training view, one
  candidate. Everything undefined is null, every file a viewer opens is written, and the
  summary says "undefined" rather than "nan"."""
  import subprocess
  import sys

  from mfsample.data import PointCloud, datasets, export_nerfstudio, load_nerfstudio, synthetic
  from mfsample.data.nerfstudio import NS_PROCESS_DATA_TRANSFORM

  config = next_views_configs.get_config("tiny")
  dataset = datasets.load_dataset(data_spec(config.data))
  xyz = np.asarray(synthetic.synthetic_gaussians(config.data.synthetic.num_gaussians, 0).means)
  export_nerfstudio(tmp_path / "capture", dataset.train.subset(range(3)),
                    PointCloud(xyz, np.full_like(xyz, 0.5)),
                    applied_transform=NS_PROCESS_DATA_TRANSFORM)
  overrides = {"data.kind": "nerfstudio", "data.path": str(tmp_path / "capture"),
               "model.init_from": "points"}
  for field, value in overrides.items():
    block, leaf = field.split(".")
    config[block][leaf] = value
  workdir = tmp_path / "work"
  results = run_next_views(config, str(workdir))
  assert (results["num_train_views"], results["num_test_views"]) == (1, 1)
  assert results["next_views"]["num_candidates"] == 1
  assert results["next_views"]["rho_u_error"] is None  # one candidate: no rank correlation
  for name in ("results.json", "next_views.json", "test/metrics.json"):
    text = (workdir / name).read_text()
    assert "NaN" not in text and "Infinity" not in text, name
    json.loads(text)
  assert (workdir / "next_views.png").stat().st_size > 10_000
  # The proposal in viewers' formats, in the capture's world: nerfstudio reads it back.
  views, _ = load_nerfstudio(workdir / "next_views", frame="original")
  # holdout_every = 8: view 0 tests; views.train_every = 2 of views 1, 2: view 2 is unused.
  candidate = dataset.train.cameras[2]
  np.testing.assert_allclose(views.cameras.world_to_camera[0], candidate.world_to_camera,
                             atol=1e-6)
  assert views.names == (f"01_{results['top_k'][0]['name']}",)
  for name in ("camera_path.json", "cameras.json", "sparse/0/images.txt",
               "uncertainty/01_" + results["top_k"][0]["name"] + ".png", "uncertainty.json",
               "captured/01_" + results["top_k"][0]["name"] + ".png"):
    assert (workdir / "next_views" / name).exists(), name
  assert results["files"]["uncertainty_ply"] == ["uncertainty_ply/coloured_by_uncertainty.ply",
                                                 "uncertainty_ply/model_colours.ply",
                                                 "uncertainty_ply/per_gaussian.ply"]
  assert all((workdir / p).stat().st_size > 1000 for p in results["files"]["uncertainty_ply"])
  # The command's summary on the finished workdir (read back, nothing recomputed).
  flags_ = [f"--config.{k}={v}" for k, v in overrides.items()]
  env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # as a user runs it
  run = subprocess.run(
      [sys.executable, str(ROOT / "experiments" / "next_views.py"),
       f"--config={ROOT / 'configs' / 'next_views.py'}:tiny", f"--workdir={workdir}", *flags_],
      capture_output=True, text=True, cwd=ROOT, env=env)
  assert run.returncode == 0, run.stderr[-3000:]
  out = run.stdout
  assert "undefined (1 candidate(s)" in out and "nan" not in out.lower(), out
  assert "cameras.json for SuperSplat" in out


# The real files of ../shared/data/real beside the checkout, or $MFSAMPLE_REAL_DATA.
BONSAI = pathlib.Path(os.environ.get("MFSAMPLE_REAL_DATA")
                      or ROOT.parent / "shared" / "data" / "real") / "bonsai_colmap"


@pytest.mark.slow
@pytest.mark.skipif(not BONSAI.is_dir(), reason=f"bonsai capture not found at {BONSAI}")
def test_the_three_frame_bonsai_capture(tmp_path):
  """The real 3-frame COLMAP capture (Mip-NeRF 360 bonsai, as 3DGS's convert.py leaves it:
  images/ and sparse/0) through the colmap variant at the tiny schedule: images_8/ is made
  from images/; valid JSON, undefined rho, the files."""
  import shutil

  pytest.importorskip("pycolmap")
  scene = tmp_path / "bonsai"
  shutil.copytree(BONSAI / "sparse", scene / "sparse")
  shutil.copytree(BONSAI / "images", scene / "images")
  config = next_views_configs.get_config("colmap,tiny")
  config.data.kind = "colmap"
  config.data.path = str(scene)
  config.data.downscale = 8
  config.model.init_from = "points"
  config.views.train_every = 4
  workdir = tmp_path / "work"
  results = run_next_views(config, str(workdir))
  assert (results["num_train_views"], results["num_test_views"]) == (1, 1)
  assert results["next_views"]["num_candidates"] == 1
  assert results["next_views"]["rho_u_error"] is None
  text = (workdir / "results.json").read_text()
  assert "NaN" not in text and json.loads(text)["top_k"][0]["name"] == "DSCF5597"
  assert (workdir / "next_views" / "cameras.json").is_file()
  assert (workdir / "uncertainty_ply" / "coloured_by_uncertainty.ply").is_file()
  assert sorted(p.name for p in (scene / "images_8").iterdir()) == [
      "DSCF5574.JPG", "DSCF5575.JPG", "DSCF5597.JPG"]
