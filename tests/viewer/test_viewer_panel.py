"""The viewer's panel and scene, per browser tab: each tab's own controls, the default step,
proposals by rank, one colour map with one bar per coloured quantity, toggles for the
frustums. Tabs are websockets that speak viser's protocol (`viewer_testlib.Tab`): no
Chromium, no training."""

import os
import time

import numpy as np
import pytest
from viewer_testlib import Tab, next_views_workdir, planning_workdir, write_round

from mfsample.viewer import app
from mfsample.viewer.runs import Step, default_step, open_run

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SEL_2 = "Ours (Sel.), seed 0: view 3 chosen on 2 views"
SEL_1 = "Ours (Sel.), seed 0: view 2 chosen on 1 view"


@pytest.fixture
def viewer(tmp_path):
  planning_workdir(tmp_path)
  viewer = app.start(tmp_path, port=0)
  viewer.workdir_path = tmp_path
  tabs = []
  viewer.open_tab = lambda: tabs.append(Tab(viewer)) or tabs[-1]
  yield viewer
  for tab in tabs:
    tab.close()
  viewer.server.stop()


def _choose(tab, handle, value, timeout=10.0):
  """`value` chosen in the tab's browser: the message a person's click sends."""
  import msgspec
  from viser import _messages

  message = _messages.GuiUpdateMessage(handle._impl.uuid, {"value": value})
  tab.socket.send(msgspec.msgpack.encode(message.as_serializable_dict()))
  deadline = time.monotonic() + timeout
  while handle.value != value:
    assert time.monotonic() < deadline, f"the server never saw {value!r}"
    time.sleep(0.02)
  with tab.tab.viewer.lock:  # the callback has run (it holds the lock while it draws)
    pass
  time.sleep(0.1)


def test_the_default_step_colours_its_candidates():
  plain = lambda key, **kw: Step(key=key, title=key, signature=(), **kw)
  scored = plain("sel", scores=np.zeros(3))
  assert default_step([]) is None
  assert default_step([plain("a"), plain("b")]).key == "b"  # none coloured: the newest
  assert default_step([scored, plain("opt")]) is scored
  lights = plain("light", q=np.eye(2))
  assert default_step([scored, lights, plain("running")]) is lights


def test_a_planning_workdir_opens_on_a_step_with_candidates_to_show(viewer):
  titles = [s.title for s in viewer.steps]
  assert titles[-1] == "Ours (Opt. Rnd.), seed 0: view 3 chosen on 2 views"  # no scores
  panel = viewer.open_tab().tab
  assert panel.step.title == SEL_2 and panel.step.scores is not None
  assert panel.bar.visible and panel.bar_label.content.startswith(
      "candidates coloured by U (as the job scored them): 0 (left) to 1 (right)")
  assert f"**{SEL_2}**" == panel.step_title.content  # the whole title, beside the dropdown
  assert f"the newest: {titles[-1]}" in panel.status.content


def test_each_tab_has_its_own_step_camera_and_toggles(viewer):
  a, b = viewer.open_tab(), viewer.open_tab()
  pa, pb = a.tab, b.tab
  assert pa is not pb and pa.scene is not pb.scene
  _choose(a, pa.step_dropdown, SEL_1)  # a person picks a step in tab a
  assert pa.step.title == SEL_1 and not pa.follow.value
  assert pb.step.title == SEL_2 and pb.follow.value  # tab b goes on following
  _choose(a, pa.show_candidates, False)
  _choose(b, pb.show_train, False)
  assert not pa.scene.get_handle_by_name("/candidates/0").visible
  assert pb.scene.get_handle_by_name("/candidates/0").visible
  assert pa.scene.get_handle_by_name("/train/0").visible
  assert not pb.scene.get_handle_by_name("/train/0").visible
  assert pa.scene.get_handle_by_name("/next/1").visible  # proposals stay
  _choose(b, pb.camera_dropdown, "candidate: candidate_005")
  assert pb.camera_info.content.startswith("**candidate: candidate_005**")
  assert pa.camera_info.content.startswith("**next view 1** · candidate candidate_001")
  # The job writes a new round: b follows it, a keeps its step and both keep their toggles.
  write_round(viewer.workdir_path, "ours_sel", 3)
  viewer.refresh()
  assert pb.step.title == "Ours (Sel.), seed 0: view 4 chosen on 3 views"
  assert pa.step.title == SEL_1
  assert not pb.scene.get_handle_by_name("/train/2").visible
  assert pb.scene.get_handle_by_name("/candidates/0").visible
  _choose(a, pa.step_dropdown, SEL_2)  # a's next step keeps a's toggles
  assert not pa.scene.get_handle_by_name("/candidates/3").visible
  assert pa.scene.get_handle_by_name("/train/1").visible


def test_candidates_are_coloured_on_magma_and_proposals_named_by_rank(viewer):
  from matplotlib import colormaps

  panel = viewer.open_tab().tab
  scores = panel.step.scores
  for i, u in enumerate(scores):
    expected = (np.asarray(colormaps["magma"](u / scores.max())[:3]) * 255).astype(np.uint8)
    assert tuple(panel.scene.get_handle_by_name(f"/candidates/{i}").color) == tuple(expected)
  assert panel.scene.get_handle_by_name("/next/1/label").text == "next view 1 (U 0.5)"
  assert panel.camera_dropdown.options[0] == "next view 1"
  assert not panel.splat_bar.visible  # the splats are not coloured by a score: no bar
  bar = app.colour_bar()
  np.testing.assert_array_equal(bar[0, 0], (np.asarray(colormaps["magma"](0.0)[:3]) * 255
                                            ).astype(np.uint8))


def test_a_candidate_without_a_score_is_grey(tmp_path):
  from mfsample.train import checkpoint as ckpt

  planning_workdir(tmp_path)
  path = tmp_path / "rounds" / "ours_sel-seed0" / "ckpt_00000002.npz"
  meta = ckpt.read_meta(str(path))
  meta["scores"][4] = None  # a non-finite U, as the job writes it
  ckpt.save_checkpoint(str(path.parent), {}, meta, keep=8)
  viewer = app.start(tmp_path, port=0)
  tab = Tab(viewer)
  try:
    panel = tab.tab
    assert tuple(panel.scene.get_handle_by_name("/candidates/4").color) == app.UNSCORED_COLOUR
    assert panel.bar_label.content.endswith("; 1 without a score, in grey")
    assert "damaged" not in panel.status.content
  finally:
    tab.close()
    viewer.server.stop()


def test_a_your_data_proposal_is_named_by_rank_not_by_its_file_name(tmp_path):
  next_views_workdir(tmp_path, steps=())  # no model: nothing to render (fast)
  viewer = app.start(tmp_path, port=0)
  tab = Tab(viewer)
  try:
    panel = tab.tab
    labels = [panel.scene.get_handle_by_name(f"/next/{r}/label").text for r in (1, 2)]
    assert labels == ["next view 1 (U 0.6)", "next view 2 (U 0.5)"]
    assert panel.camera_dropdown.options == ("next view 1", "next view 2")
    assert "scene-" not in " ".join(labels)  # the job's file name, shown in the panel only
    assert panel.camera_info.content.startswith("**next view 1** · a new pose (scene-")
  finally:
    tab.close()
    viewer.server.stop()


def test_the_docs_screenshot_command_writes_into_a_workdir():
  import glob

  commands = []
  for page in glob.glob(os.path.join(ROOT, "docs", "*.md")) + [os.path.join(ROOT, "README.md")]:
    with open(page, encoding="utf-8") as f:
      commands += [line for line in f if line.startswith("python") and "--screenshot=" in line]
  assert commands, "docs/viewer.md shows the --screenshot command"
  for line in commands:
    path = line.split("--screenshot=")[1].split()[0]
    assert path.startswith("workdirs/"), line  # never a tracked file of the docs


def test_the_default_step_of_a_run_opened_as_a_library_call(tmp_path):
  planning_workdir(tmp_path)
  assert default_step(open_run(tmp_path).steps()).title == SEL_2


def test_a_step_that_cannot_be_drawn_is_said_in_its_tab_alone(viewer):
  a, b = viewer.open_tab(), viewer.open_tab()

  def broken(step):
    raise ValueError("no room for frustums")

  a.tab._draw_cameras = broken
  _choose(a, a.tab.step_dropdown, SEL_1)
  assert "**drawing the step failed** (ValueError: no room for frustums)" in (
      a.tab.status.content)
  assert "failed" not in b.tab.status.content
  del a.tab._draw_cameras
  _choose(a, a.tab.step_dropdown, SEL_2)  # the next step draws, and the message goes
  assert "failed" not in a.tab.status.content
  assert a.tab.scene.get_handle_by_name("/candidates/0") is not None
