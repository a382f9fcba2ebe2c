"""Tests of mfsample.viewer: bad workdirs and ports, the models it reads, the rounds camera
planning records for it, and its page in headless Chromium.

The browser test needs Chromium (Debian's `chromium`; `.ci/run` installs it) and skips,
saying so, only where none is installed.
"""

import json
import os
import socket
import subprocess
import sys
import time

import jax
import numpy as np
import pytest
from planning_testlib import random_model, tiny_config, tiny_pool
from viewer_testlib import Tab, next_views_workdir

from mfsample import config_record
from mfsample.planning import rounds, strategies
from mfsample.planning.config import strategy_settings
from mfsample.planning.pool import stack_cameras
from mfsample.train import checkpoint as ckpt
from mfsample.viewer import app, models
from mfsample.viewer.browser import Browser, find_chromium
from mfsample.viewer.runs import RunError, default_step, open_run

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


# ------------------------------------------------------------------ bad input


def test_a_folder_without_a_run_is_refused(tmp_path):
  with pytest.raises(RunError, match="no such folder"):
    open_run(tmp_path / "missing")
  with pytest.raises(RunError, match="holds no run: no config.json"):
    open_run(tmp_path)
  (tmp_path / "config.json").write_text("{\"seed\": ")  # a job killed mid-write
  with pytest.raises(RunError, match="is not a JSON object"):
    open_run(tmp_path)


def test_a_run_of_an_unknown_kind_is_refused(tmp_path):
  from configs import train

  config_record.write_config(train.get_config("tiny"), str(tmp_path),
                           {"job": "training"})  # experiments/train.py's
  with pytest.raises(RunError, match="of the 'training' job, which the viewer does not show"
                                     ".*camera planning"):
    open_run(tmp_path)
  config_record.write_config(train.get_config("tiny"), str(tmp_path))  # who wrote it: unknown
  with pytest.raises(RunError, match="does not record which job wrote"):
    open_run(tmp_path)


def _planning_config(config, workdir):
  """`config.json` of a camera-planning workdir, as the job writes it."""
  config_record.write_config(config, str(workdir), {"job": "camera_planning"})


def test_a_port_in_use_is_refused_by_name(tmp_path):
  _planning_config(tiny_config(), tmp_path)
  with socket.socket() as taken:
    taken.bind(("127.0.0.1", 0))
    taken.listen()
    port = taken.getsockname()[1]
    with pytest.raises(app.ViewerError, match=f"port {port} on 127.0.0.1 is in use"):
      app.start(tmp_path, port=port)


def _command(*args):
  return subprocess.run([sys.executable, os.path.join(ROOT, "experiments", "viewer.py"), *args],
                        capture_output=True, text=True, timeout=120, cwd=ROOT)


@pytest.mark.slow
def test_the_command_says_what_is_wrong_without_a_traceback(tmp_path):
  # A screenshot has no run to wait for (the server waits: test_viewer_damage.py).
  empty = _command(f"--workdir={tmp_path}", f"--screenshot={tmp_path / 'page.png'}")
  assert empty.returncode == 1 and "Traceback" not in empty.stderr
  assert f"error: {tmp_path} holds no run" in empty.stderr
  _planning_config(tiny_config(), tmp_path)
  with socket.socket() as taken:
    taken.bind(("127.0.0.1", 0))
    taken.listen()
    port = taken.getsockname()[1]
    busy = _command(f"--workdir={tmp_path}", f"--port={port}")
  assert busy.returncode == 1 and "Traceback" not in busy.stderr
  assert f"error: port {port} on 127.0.0.1 is in use" in busy.stderr


# ------------------------------------------------------------------ models and rounds


def test_a_saved_model_reads_back_as_it_was(tmp_path):
  model = random_model(num=20)
  path = ckpt.save_checkpoint(str(tmp_path), model,
                              {"step": 1, "sampler": model.spec.to_dict()})
  read = models.read_model(path)
  assert read.spec == model.spec  # as recorded: kind, rank, groups, bounds, z source
  assert read.spec.kind == "lowrank" and read.spec.rank == 2
  assert set(model.params.b_hat) <= set(read.spec.groups)
  for a, b in zip(jax.tree.leaves(model), jax.tree.leaves(read), strict=True):
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
  centres, cov, rgb, opacity = models.splats(read, eye=np.array([0.0, -3.0, 0.0]))
  live = np.asarray(model.mask)
  assert centres.shape == (live.sum(), 3) and cov.shape == (live.sum(), 3, 3)
  np.testing.assert_allclose(cov, np.swapaxes(cov, 1, 2), atol=1e-7)
  assert np.all(np.linalg.eigvalsh(cov.astype(np.float64)) > 0)
  assert rgb.min() >= 0 and rgb.max() <= 1 and opacity.shape == (live.sum(), 1)
  with pytest.raises(models.ModelFileError, match="holds no model"):
    models.read_model(ckpt.save_checkpoint(str(tmp_path / "empty"), {}, {"step": 1}))
  with pytest.raises(models.ModelFileError, match="does not record the sampler"):
    models.read_model(ckpt.save_checkpoint(str(tmp_path / "old"), model, {"step": 1}))
  with pytest.raises(models.ModelFileError, match="do not hold one model"):
    bad = model.replace(mask=np.asarray(model.mask)[:5])
    models.read_model(ckpt.save_checkpoint(str(tmp_path / "bad"), bad, {
        "step": 1, "sampler": model.spec.to_dict()}))
  with open(path, "r+b") as f:  # cut short: as a job's checkpoint, unreadable
    f.truncate(100)
  with pytest.raises(ckpt.CorruptCheckpointError, match="ckpt_00000001.npz is unreadable"):
    models.read_model(path)


def _round(workdir, strategy, pool, model, views):
  """One round of `strategy` on the candidate `views` (indices), recorded in `workdir`."""
  config = tiny_config()
  available = np.ones(len(pool.candidates), bool)
  available[list(views)] = False
  inputs = strategies.Inputs(model, stack_cameras([pool.candidates.cameras[i] for i in views]),
                             pool.candidates.cameras, available, pool.sphere, pool.bounds,
                             pool.background, max_views=config.max_views)
  recorded = rounds.record_rounds(strategy, str(workdir / rounds.DIRECTORY), "ours_sel-seed0", 0,
                                  keep_models=True, keep=config.max_views)
  return recorded.select(inputs, jax.random.PRNGKey(len(views)))


@pytest.fixture(scope="module")
def planning_workdir(tmp_path_factory):
  """A camera-planning workdir holding one round of Ours (Sel.) on an untrained model, written
  by `record_rounds` as the planning job writes it."""
  workdir = tmp_path_factory.mktemp("planning")
  config = tiny_config()
  config.strategies = ("ours_sel",)
  _planning_config(config, workdir)
  pool, model = tiny_pool(), random_model(num=80)
  strategy = strategies.make_strategy("ours_sel", strategy_settings(config))
  choice = _round(workdir, strategy, pool, model, [0])
  return workdir, strategy, pool, model, choice


@pytest.mark.slow
def test_a_round_records_the_scores_the_choice_and_the_model(planning_workdir):
  workdir, _, pool, model, choice = planning_workdir
  (path,) = ckpt.list_checkpoints(os.path.join(workdir, "rounds", "ours_sel-seed0"))
  meta = ckpt.read_meta(path)
  assert meta["step"] == 1 and meta["train"] == [0] and meta["chosen"]["index"] == choice.index
  np.testing.assert_allclose(meta["scores"], choice.info["scores"])
  assert meta["model"] == {"sampler": model.spec.to_dict()}
  read = models.read_model(path)
  np.testing.assert_array_equal(read.params.b_hat["means"], model.params.b_hat["means"])
  with np.load(os.path.join(workdir, "rounds", "candidates.npz")) as data:
    np.testing.assert_allclose(data["world_to_camera"], pool.candidates.cameras.world_to_camera)
  (step,) = open_run(workdir).steps()
  assert step.model_path == path and step.proposals[0].index == choice.index
  assert step.title == "Ours (Sel.), seed 0: view 2 chosen on 1 view"


# ------------------------------------------------------------------ the page


@pytest.mark.slow
def test_the_panel_shows_u_as_the_job_defines_it(planning_workdir):
  """U of a candidate on screen is the job's: the same samples, at the size the job scores
  at, so it equals the score the round recorded."""
  workdir, _, pool, _, choice = planning_workdir
  viewer = app.start(workdir, port=0)
  tab = None
  try:
    tab = Tab(viewer)
    panel = tab.tab
    step = panel.step
    model = viewer.run.model(step)
    scores = np.asarray(choice.info["scores"])
    down = tiny_config().strategy.score_downscale
    for i in range(len(pool.candidates)):
      camera = step.candidates[0][i]
      rgb, pmap, u = viewer.renders(step, model, camera, ("candidates", i))
      assert rgb.shape == (camera.height, camera.width, 3)
      assert pmap.shape == (camera.height // down, camera.width // down)
      np.testing.assert_allclose(u, scores[i], rtol=1e-4)
    info = panel.camera_info.content  # the first proposal, shown on opening
    assert info.startswith(f"**next view 1** · candidate {step.candidates[1][choice.index]}")
    w, h = pool.candidates.cameras.width // down, pool.candidates.cameras.height // down
    assert (f"U (Eq. 10) at {w} x {h}, 1/{down} of the image as the job scores, M = "
            f"{tiny_config().strategy.ours.select_samples}: ") in info
    assert f"U as the job scored it: {scores[choice.index]:.4g}" in info
    assert "ground truth · mean render" in info and panel.views_image.visible
  finally:
    if tab is not None:
      tab.close()
    viewer.server.stop()


@pytest.mark.slow
def test_the_your_data_panel_shows_each_view_with_its_ground_truth(tmp_path):
  next_views_workdir(tmp_path, inputs=True)
  viewer = app.start(tmp_path, port=0)
  tab = None
  try:
    assert viewer.run.inputs_error == ""
    tab = Tab(viewer)
    panel = tab.tab
    info = panel.camera_info.content
    assert info.startswith("**next view 1** · candidate ")
    assert "ground truth · mean render (32 x 32) · U map (32 x 32;" in info
    truth = viewer.run.ground_truth(panel.step, "candidates", 5)
    assert truth.shape == (32, 32, 3) and truth.std() > 0
    assert viewer.run.ground_truth(panel.step, "train", 0).shape == (32, 32, 3)
  finally:
    if tab is not None:
      tab.close()
    viewer.server.stop()


@pytest.mark.slow
def test_the_page_shows_the_plan_and_follows_the_run(planning_workdir, tmp_path):
  """The viewer on a planning workdir, loaded in headless Chromium: the scene's objects (by
  viser's API and by the page's scene tree), the proposal's ground truth, render and U map in
  view, and a round written while it runs appearing without a restart."""
  if find_chromium() is None:
    pytest.skip("no Chromium on PATH: apt-get install chromium (.ci/run installs it) to run "
                "the viewer's browser test")
  import viser

  workdir, strategy, pool, model, choice = planning_workdir
  t0, cpu0 = time.perf_counter(), time.process_time()
  viewer = app.start(workdir, port=0)
  try:
    first = default_step(viewer.steps).title
    with Browser(size=(1280, 900)) as browser:
      browser.open(f"http://127.0.0.1:{viewer.server.get_port()}/")
      browser.wait_for_text(first)
      (tab,) = viewer.tabs.values()
      # The page shows the step's title before the tab has drawn the step (the splats' colours
      # are rendered first); the tab draws it holding the viewer's lock.
      with viewer.lock:
        scene = tab.scene
      assert isinstance(scene.get_handle_by_name("/splats"), viser.GaussianSplatHandle)
      assert isinstance(scene.get_handle_by_name("/train/0"), viser.CameraFrustumHandle)
      assert isinstance(scene.get_handle_by_name("/next/1"), viser.CameraFrustumHandle)
      scores = np.asarray(choice.info["scores"])
      colours = app.colormap(scores)
      for i in range(len(pool.candidates)):  # the candidates are coloured by U
        assert tuple(scene.get_handle_by_name(f"/candidates/{i}").color) == tuple(colours[i])
      # The page's scene tree (viser's Dev Settings panel) lists the scene's nodes. The panel
      # shows only briefly as the page loads, so its rows are read from the page's DOM, where
      # they stay when it is hidden.
      nodes = ("/splats", "/train", "/candidates", "/next")
      assert browser.wait_for(" && ".join(
          f"document.body.textContent.includes({json.dumps(n)})" for n in nodes))
      # The panel follows the scene (the proposal's U is rendered after it).
      for shown in ("candidates coloured by U", "next view 1",
                    f"U as the job scored it: {scores[choice.index]:.4g}"):
        browser.wait_for_text(shown)
      # The ground truth, render and U map side by side, decoded and inside the window.
      strip = (f"Array.from(document.images).filter(i => i.complete && "
               f"i.naturalHeight == {app.STRIP_HEIGHT})")
      assert browser.wait_for(f"{strip}.length == 1")
      assert browser.evaluate(f"{strip}[0].getBoundingClientRect().bottom <= "
                              "window.innerHeight")

      # The job writes its next round: the page follows without a restart.
      _round(workdir, strategy, pool, model, [0, choice.index])
      viewer.refresh()
      second = tab.step.title
      assert second != first and "on 2 views" in second
      assert isinstance(scene.get_handle_by_name("/train/1"), viser.CameraFrustumHandle)
      browser.wait_for_text(second)

      # The splats coloured by each Gaussian's share of U over the candidates, on a bar of
      # their own.
      before = scene.get_handle_by_name("/splats")
      tab.splat_colour.value = "share of U"
      assert scene.get_handle_by_name("/splats") is not before
      assert tab.splat_bar.visible and tab.bar.visible
      browser.wait_for_text("splats coloured by share of U")
      browser.screenshot(str(tmp_path / "viewer.png"))
  finally:
    viewer.server.stop()
  from PIL import Image

  with Image.open(tmp_path / "viewer.png") as shot:
    pixels = np.asarray(shot.convert("RGB"))
  assert pixels.shape[:2] == (900, 1280) and pixels.std() > 10  # not a blank page
  print(f"browser test: {time.perf_counter() - t0:.1f} s, {time.process_time() - cpu0:.1f} s "
        "of this process's CPU time")


@pytest.mark.slow
def test_a_screenshot_is_written_where_asked(planning_workdir, tmp_path):
  if find_chromium() is None:
    pytest.skip("no Chromium on PATH: apt-get install chromium to run the viewer's "
                "screenshot test")
  path = tmp_path / "new folder" / "page.png"
  app.screenshot(planning_workdir[0], str(path), settle=1.0)
  assert path.is_file() and sorted(os.listdir(path.parent)) == ["page.png"]


@pytest.mark.slow
def test_the_server_states_its_address_and_binds_to_this_machine(planning_workdir):
  workdir = planning_workdir[0]
  said = []

  def on_start(message):  # what the command prints; then a Ctrl-C
    said.append(message)
    raise KeyboardInterrupt

  app.serve(workdir, port=0, on_start=on_start)
  (message,) = said
  assert "camera planning" in message and "bound to 127.0.0.1" in message
  assert int(message.split("http://localhost:")[1].split()[0]) > 0  # the port bound


def test_find_chromium_takes_the_first_browser_on_path(tmp_path, monkeypatch):
  from mfsample.viewer import browser

  monkeypatch.setenv("PATH", str(tmp_path))
  assert browser.find_chromium() is None
  with pytest.raises(browser.BrowserError, match="no Chromium on PATH"):
    browser.Browser()
  fake = tmp_path / "google-chrome"
  fake.write_text("#!/bin/sh\n")
  fake.chmod(0o755)
  assert browser.find_chromium() == str(fake)


def test_the_viewer_command_refuses_a_workdir_of_no_known_job_in_one_line(tmp_path):
  """`mfsample viewer` (`viewer.command`) on a workdir whose config.json names no job."""
  (tmp_path / "config.json").write_text('{"seed": 0}')
  run = subprocess.run([sys.executable, "-m", "mfsample", "viewer", f"--workdir={tmp_path}",
                        "--port=0"], capture_output=True, text=True, timeout=120)
  assert run.returncode == 1 and "Traceback" not in run.stderr, run.stderr
  assert "does not record which job wrote" in run.stderr
