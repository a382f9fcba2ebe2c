"""The viewer on damaged workdirs: every damaged file is named in the panel and the rest of
the run is shown, as the jobs recover (a checkpoint cut short: the one before it); damage
appearing while it watches a run does not end it; started before a job wrote config.json,
it waits for the run. Tiny workdirs written by `viewer_testlib`: no training, no data."""

import json
import os

import numpy as np
import pytest
from viewer_testlib import (
    Tab,
    next_views_workdir,
    planning_workdir,
    truncate,
    write_json,
)

from mfsample import config_record
from mfsample.train import checkpoint as ckpt
from mfsample.viewer import app
from mfsample.viewer.runs import NoRunYet, RunError, open_run

CKPT_10, CKPT_20 = "checkpoints/ckpt_00000010.npz", "checkpoints/ckpt_00000020.npz"


def _steps(workdir):
  run = open_run(workdir)
  return run, run.steps()


# ------------------------------------------------------------------ checkpoints


def test_a_truncated_newest_checkpoint_gives_way_to_the_one_the_job_resumes_from(tmp_path):
  next_views_workdir(tmp_path)
  truncate(tmp_path / CKPT_20)
  run, (step,) = _steps(tmp_path)
  # The job's own choice (`restore_latest` reads through the same function).
  path, _, skipped = ckpt.newest_readable(str(tmp_path / "checkpoints"), ckpt.read_arrays)
  assert step.model_path == path == str(tmp_path / CKPT_10)
  assert [p for p, _ in skipped] == [str(tmp_path / CKPT_20)]
  assert run.model(step) is not None
  (problem,) = run.problems
  assert problem.startswith(f"checkpoint {CKPT_20} is unreadable (BadZipFile")
  assert f"{CKPT_20} cannot be read: showing {CKPT_10}, the checkpoint the job resumes from" in (
      step.note)
  assert step.scores is not None and len(step.proposals) == 2  # the rest is shown


@pytest.mark.parametrize("damage", ["zeros", "empty", "half", "no model"])
def test_every_unreadable_checkpoint_is_named(tmp_path, damage):
  next_views_workdir(tmp_path)
  newest = tmp_path / CKPT_20
  if damage == "zeros":
    newest.write_bytes(bytes(newest.stat().st_size))
  elif damage == "empty":
    newest.write_bytes(b"")
  elif damage == "half":
    truncate(newest, 0.9)
  else:  # readable, but a state without a model (another program's file of that name)
    ckpt.save_checkpoint(str(tmp_path / "checkpoints"), {}, {"step": 20}, keep=2)
  run, (step,) = _steps(tmp_path)
  assert step.model_path == str(tmp_path / CKPT_10)
  assert len(run.problems) == 1 and CKPT_20 in run.problems[0]


def test_no_readable_checkpoint_leaves_a_run_without_a_model(tmp_path):
  next_views_workdir(tmp_path)
  truncate(tmp_path / CKPT_10)
  truncate(tmp_path / CKPT_20)
  run, (step,) = _steps(tmp_path)
  assert step.model_path is None and run.model(step) is None
  assert "no checkpoint in checkpoints can be read" in step.note
  assert sorted(p.split(" is unreadable")[0] for p in run.problems) == [
      f"checkpoint {CKPT_10}", f"checkpoint {CKPT_20}"]
  assert len(step.proposals) == 2  # the proposal's poses are still drawn


def test_a_checkpoint_damaged_after_it_was_read_is_named_when_read_again(tmp_path):
  next_views_workdir(tmp_path, steps=(10,))
  run, (step,) = _steps(tmp_path)
  assert run.model(step) is not None
  truncate(tmp_path / CKPT_10)
  assert run.model(step) is None
  assert any(p.startswith(f"checkpoint {CKPT_10} is unreadable") for p in run.problems)


# ------------------------------------------------------------------ records


def _record(workdir):
  return json.loads((workdir / "next_views.json").read_text())


@pytest.mark.parametrize("u, said", [
    (["a", "b", "c", "d", "e", "f"], "u[0] is 'a', not a number"),
    ([0.1, 0.2, "0.3", 0.4, 0.5, 0.6], "u[2] is '0.3', not a number"),
    ([0.1, True, 0.3, 0.4, 0.5, 0.6], "u[1] is True, not a number"),
    ([[0.1, 0.2]] * 6, "u[0] is [0.1, 0.2], not a number"),
    ({"a": 1}, "u is an object, not a list of numbers"),
    ("0.1 0.2", "u is a string, not a list of numbers"),
])
def test_a_u_that_is_not_a_list_of_numbers_is_named(tmp_path, u, said):
  next_views_workdir(tmp_path)
  write_json(tmp_path / "next_views.json", {**_record(tmp_path), "u": u})
  run, (step,) = _steps(tmp_path)
  assert step.scores is None  # candidates unscored, ...
  assert len(step.proposals) == 2 and step.model_path  # ... the rest shown
  (problem,) = run.problems
  assert problem == f"next_views.json: {said}: the candidates are shown unscored"


def test_u_of_non_finite_values_is_read_as_the_job_writes_it(tmp_path):
  next_views_workdir(tmp_path)
  write_json(tmp_path / "next_views.json", {**_record(tmp_path),
                                            "u": [0.1, None, 0.3, 0.4, 0.5, 0.6]})
  run, (step,) = _steps(tmp_path)
  assert run.problems == () and np.isnan(step.scores[1]) and step.scores[2] == 0.3


@pytest.mark.parametrize("name, content, said", [
    ("results.json", [1, 2], "results.json: holds a list where the job writes a JSON object"),
    ("results.json", "{\"steps\": ", "results.json: unreadable or not JSON (JSONDecodeError"),
    ("results.json", {"steps": "many"}, "results.json: steps is 'many', not a number of steps"),
    ("next_views.json", [1, 2], "next_views.json: holds a list where the job writes"),
    ("next_views.json", "\x00\x01", "next_views.json: unreadable or not JSON"),
])
def test_a_record_of_another_shape_is_named(tmp_path, name, content, said):
  next_views_workdir(tmp_path)
  path = tmp_path / name
  path.write_text(content if isinstance(content, str) else json.dumps(content))
  run, (step,) = _steps(tmp_path)
  (problem,) = run.problems
  assert problem.startswith(said), problem
  assert step.model_path == str(tmp_path / CKPT_20)
  if name == "results.json":  # the proposal is shown, without the step count
    assert step.title == "next 2 of 6 candidates" and step.scores is not None


@pytest.mark.parametrize("edit, said", [
    (lambda t: t[0].pop("intrinsics"), "top_k[0] lacks 'intrinsics'"),
    (lambda t: t[0].update(world_to_camera=[[float("nan")] * 4] * 4),
     "top_k[0].world_to_camera holds non-finite values"),
    (lambda t: t[0].update(world_to_camera=[1, 2, 3]), "top_k[0].world_to_camera has shape"),
    (lambda t: t[0].update(world_to_camera=np.zeros((4, 4)).tolist()),
     "top_k[0].world_to_camera holds a matrix whose rotation is singular"),
    (lambda t: t[0]["intrinsics"].update(fx=-1), "top_k[0]: focal lengths"),
    (lambda t: t[0]["intrinsics"].update(width="wide"), "top_k[0]: intrinsics that are not"),
    (lambda t: t[0].update(u="high"), "top_k[0].u is 'high', not a number"),
    (lambda t: t[0].update(rank="first"), "top_k[0].rank is 'first'"),
    (lambda t: t.__setitem__(0, "a view"), "top_k[0] is a string, not an object"),
])
def test_a_malformed_proposal_is_named_and_the_others_drawn(tmp_path, edit, said):
  next_views_workdir(tmp_path)
  record = _record(tmp_path)
  edit(record["top_k"])
  write_json(tmp_path / "next_views.json", record)
  run, (step,) = _steps(tmp_path)
  assert [p.rank for p in step.proposals] == [2] and step.scores is not None
  (problem,) = run.problems
  assert problem.startswith(f"next_views.json: {said}") and problem.endswith("(not drawn)")


# ------------------------------------------------------------------ camera planning


def _round_meta(workdir, name="ours_sel", views=2):
  path = workdir / "rounds" / f"{name}-seed0" / f"ckpt_{views:08d}.npz"
  return path, ckpt.read_meta(str(path))


def _rewrite_round(workdir, meta_edit, name="ours_sel", views=2):
  path, meta = _round_meta(workdir, name, views)
  meta_edit(meta)
  ckpt.save_checkpoint(str(path.parent), {}, meta, keep=8)
  return path


@pytest.mark.parametrize("edit, said", [
    (lambda m: m.update(scores=["x"] * 8), "scores[0] is 'x', not a number: the candidates"),
    (lambda m: m.update(scores=[0.5] * 3), "scores holds 3 values, not 8"),
    (lambda m: m["chosen"].update(index=99), "chosen.index is 99, not an index of the 8"),
    (lambda m: m.update(train=[0, "one"]), "train[1] is 'one', not an index"),
    (lambda m: m.update(train=[0, 99]), "train[1] is 99, not an index of the 8 candidates"),
    (lambda m: m.update(train_world_to_camera="far"), "train_world_to_camera is not a list"),
    (lambda m: m.update(chosen=[1]), "chosen is a list"),
    (lambda m: m.pop("seed"), "KeyError: 'seed'"),
])
def test_a_malformed_round_is_named_and_the_other_rounds_shown(tmp_path, edit, said):
  planning_workdir(tmp_path)
  path = _rewrite_round(tmp_path, edit)
  run, steps = _steps(tmp_path)
  (problem,) = run.problems
  assert problem.startswith(f"{path.relative_to(tmp_path)}: ") and said in problem, problem
  titles = [s.title for s in steps]
  assert "Ours (Sel.), seed 0: view 2 chosen on 1 view" in titles
  assert len(steps) == (4 if "unscored" in problem else 3)


def test_damaged_planning_files_are_named(tmp_path):
  planning_workdir(tmp_path)
  truncate(tmp_path / "rounds" / "ours_sel-seed0" / "ckpt_00000002.npz")
  (tmp_path / "runs").mkdir()
  (tmp_path / "runs" / "ours_opt_rnd-seed0.json").write_text("[1, 2]")
  write_json(tmp_path / "runs" / "ours_sel-seed0.json",
             {"strategy": "ours_sel", "seed": 0, "indices": [0, 1], "world_to_camera": "x",
              "scores": [0, 1]})
  run, steps = _steps(tmp_path)
  assert len(steps) == 3
  lines = sorted(run.problems)
  assert lines[0].startswith("checkpoint rounds/ours_sel-seed0/ckpt_00000002.npz is "
                             "unreadable (BadZipFile") and lines[0].endswith("not shown")
  assert lines[1].startswith("runs/ours_opt_rnd-seed0.json: holds a list")
  assert lines[2].startswith("runs/ours_sel-seed0.json: the run's record is malformed "
                             "(world_to_camera is not a list of 4 x 4 matrices")
  # The pool's cameras damaged: named, and without inputs the rounds lose their cameras.
  (tmp_path / "rounds" / "candidates.npz").write_bytes(b"PK\x03\x04 not a zip")
  run, steps = _steps(tmp_path)
  assert any(p.startswith("rounds/candidates.npz: unreadable (BadZipFile") for p in
             run.problems)
  assert all(s.candidates is None for s in steps) and len(steps) == 3


# ------------------------------------------------------------------ light planning


def _light_workdir(workdir):
  from configs import light_planning

  config = light_planning.get_config("tiny")
  config.data.kind = "colmap"  # no inputs: the lights only
  config_record.write_config(config, str(workdir), {"job": "light_planning"})
  n = int(config.model.light_coeffs)
  q = np.eye(n).tolist()
  (workdir / "shared").mkdir()
  (workdir / "runs").mkdir()
  write_json(workdir / "shared" / "record.json", {"q": q})
  light = np.ones(n).tolist()
  write_json(workdir / "runs" / "ours.json", {"phases": [
      {"lights": 2, "light": light, "q": q}, {"lights": 3, "light": light, "q": q}]})
  return n


def test_a_truncated_light_checkpoint_gives_way_to_the_one_before(tmp_path):
  from planning_testlib import random_model

  _light_workdir(tmp_path)
  model = random_model(num=20)
  for step in (1, 2):
    ckpt.save_checkpoint(str(tmp_path / "shared"), model,
                         {"step": step, "sampler": model.spec.to_dict()})
  truncate(tmp_path / "shared" / "ckpt_00000002.npz")
  run, steps = _steps(tmp_path)
  assert steps[0].model_path == str(tmp_path / "shared" / "ckpt_00000001.npz")
  assert "shared/ckpt_00000002.npz cannot be read: showing shared/ckpt_00000001.npz" in (
      steps[0].note)
  (problem,) = run.problems
  assert problem.startswith("checkpoint shared/ckpt_00000002.npz is unreadable")


def test_damaged_light_records_are_named(tmp_path):
  n = _light_workdir(tmp_path)
  run, steps = _steps(tmp_path)
  assert [s.key for s in steps] == ["shared", "ours/2", "ours/3"] and run.problems == ()
  write_json(tmp_path / "shared" / "record.json", {"q": [["a"] * n] * n})
  record = json.loads((tmp_path / "runs" / "ours.json").read_text())
  record["phases"][1]["q"] = [[1.0] * n] * (n - 1)
  write_json(tmp_path / "runs" / "ours.json", record)
  run, steps = _steps(tmp_path)
  assert [s.key for s in steps] == ["ours/2"]
  assert sorted(run.problems) == [
      "runs/ours.json: phases[1].q has 3 rows, not 4; the lights from there on are not shown",
      "shared/record.json: q[0][0] is 'a', not a number; the first phase is not shown"]


# ------------------------------------------------------------------ a run watched


def test_damage_appearing_while_the_viewer_watches_does_not_end_it(tmp_path):
  planning_workdir(tmp_path)
  viewer = app.start(tmp_path, port=0)
  tab = None
  try:
    tab = Tab(viewer)
    panel = tab.tab
    shown = panel.step.title
    assert "damaged" not in panel.status.content and panel.problems.content == ""
    damage = [
        lambda: truncate(tmp_path / "rounds" / "ours_opt_rnd-seed0" / "ckpt_00000002.npz"),
        lambda: (tmp_path / "rounds" / "candidates.npz").write_bytes(b"garbage"),
        lambda: _rewrite_round(tmp_path, lambda m: m.update(scores="none"), views=1),
    ]
    for i, harm in enumerate(damage):
      harm()
      viewer.refresh()  # what the loop of `serve` calls every poll
      assert panel.problems.content.count("\n- ") == i + 1, panel.problems.content
      assert f"**{i + 1} damaged file(s)**, listed at the end" in panel.status.content
    assert "rounds/candidates.npz: unreadable" in panel.problems.content
    assert "rounds/ours_opt_rnd-seed0/ckpt_00000002.npz is unreadable" in panel.problems.content
    assert panel.step.title == shown  # still drawn, without its cameras now
    # Whatever else a read raises is shown too, and the last state read stays up.
    steps = viewer.steps

    def broken():
      raise RuntimeError("disk on fire")

    viewer.run.steps = broken
    viewer.refresh()
    assert "failed (RuntimeError: disk on fire)" in panel.status.content
    assert viewer.steps is steps and panel.step.title == shown
    del viewer.run.steps  # mended: the next poll clears the message
    viewer.refresh()
    assert "disk on fire" not in panel.status.content
  finally:
    if tab is not None:
      tab.close()
    viewer.server.stop()


def test_started_before_the_job_the_viewer_waits_for_the_run(tmp_path):
  workdir = tmp_path / "run"
  with pytest.raises(NoRunYet, match="no such folder"):
    app.start(workdir, port=0)  # as --screenshot does: nothing to wait for
  viewer = app.start(workdir, port=0, wait=True)
  tab = None
  try:
    assert viewer.run is None and "waiting for a job to write" in viewer.waiting
    tab = Tab(viewer)
    assert "waiting for a job to write" in tab.tab.status.content
    assert "no run yet" in tab.tab.header.content
    workdir.mkdir()
    viewer.refresh()
    assert "holds no run: no config.json" in tab.tab.status.content
    (workdir / "config.json").write_text("{\"seed\": ")  # a config of someone else's writer
    viewer.refresh()
    assert "is not a JSON object" in tab.tab.status.content and viewer.run is None
    os.remove(workdir / "config.json")
    planning_workdir(workdir)  # the job starts
    viewer.refresh()
    assert viewer.run is not None and viewer.waiting == ""
    assert "camera planning" in tab.tab.header.content
    assert tab.tab.step.title == "Ours (Sel.), seed 0: view 3 chosen on 2 views"
    assert "waiting" not in tab.tab.status.content
  finally:
    if tab is not None:
      tab.close()
    viewer.server.stop()


def test_serve_says_it_waits(tmp_path):
  said = []

  def on_start(message):
    said.append(message)
    raise KeyboardInterrupt

  app.serve(tmp_path, port=0, on_start=on_start)
  (message,) = said
  assert f"no run yet (waiting for a job to write {tmp_path}: {tmp_path} holds no run" in (
      message)


def test_a_run_the_viewer_cannot_show_still_ends_the_command(tmp_path):
  from configs import train

  config_record.write_config(train.get_config("tiny"), str(tmp_path), {"job": "training"})
  with pytest.raises(RunError, match="'training' job"):
    app.start(tmp_path, port=0, wait=True)
