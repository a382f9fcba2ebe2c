"""Result files: written whole, and resumed only by a call that wrote them."""

import json

import pytest

from mfsample._json import read_resumable_rows, reusable_rows, write_json


def test_write_json_leaves_no_temporary_file_and_makes_its_folder(tmp_path):
  path = tmp_path / "new" / "out.json"
  write_json(str(path), {"a": [1, 2]})
  assert json.loads(path.read_text()) == {"a": [1, 2]}
  assert [p.name for p in path.parent.iterdir()] == ["out.json"]


def test_resumable_rows_come_back_only_to_the_same_header(tmp_path):
  path = str(tmp_path / "rows.json")
  header = {"results": "r.json", "final_train": {"steps": 600, "views": [1, 2]}}
  assert read_resumable_rows(path, header) == []  # nothing yet: start afresh
  write_json(path, {"header": header, "rows": [{"seed": 0, "psnr": 20.5}]})
  assert read_resumable_rows(path, header) == [{"seed": 0, "psnr": 20.5}]
  with pytest.raises(ValueError, match="other arguments; pass --out"):
    read_resumable_rows(path, {**header, "results": "other.json"})


def _run(strategy, seed, indices):
  return {"strategy": strategy, "seed": seed, "indices": indices,
          "world_to_camera": [[[float(i)]] for i in indices]}


def test_rows_are_reused_only_where_they_are_the_same_model(tmp_path):
  header = {"results": str(tmp_path / "old_results.json"), "final_train": {"steps": 2000},
            "init_offset": 1000}
  old_runs = [_run("far", 0, [0, 1, 2, 3]), _run("sel", 0, [0, 4, 5, 6])]
  write_json(str(tmp_path / "old_results.json"), {"runs": old_runs})

  def row(strategy, views, train_seed=0, from_run_record=False):
    return {"strategy": strategy, "seed": 0, "views": views, "steps": 2000,
            "train_seed": train_seed, "from_run_record": from_run_record, "psnr": 20.0}

  rows = [row("far", 2), row("far", 4), row("sel", 2), row("sel", 4),
          row("far", 4, train_seed=1000), row("far", 3, from_run_record=True)]
  old = str(tmp_path / "old_final.json")
  write_json(old, {"header": header, "rows": rows})
  # This call's sel run shares its first three views with the old one, not the fourth.
  runs = [_run("far", 0, [0, 1, 2, 3]), _run("sel", 0, [0, 4, 5, 7])]
  wanted = {("far", 0, 2, 2000, 0), ("far", 0, 4, 2000, 0), ("sel", 0, 2, 2000, 0),
            ("sel", 0, 4, 2000, 0), ("far", 0, 3, 2000, 0)}
  reused = reusable_rows(old, {**header, "results": "new.json"}, runs, wanted)
  assert [(r["strategy"], r["views"]) for r in reused] == [("far", 2), ("far", 4), ("sel", 2)]
  assert all(r["reused_from"] == old for r in reused)
  # A row already done here (not wanted) is not taken again.
  assert len(reusable_rows(old, header, runs, wanted - {("far", 0, 2, 2000, 0)})) == 2
  for field, other in (("final_train", {"steps": 600}), ("init_offset", 7)):
    with pytest.raises(ValueError, match=f"another {field}"):
      reusable_rows(old, {**header, field: other}, runs, wanted)
