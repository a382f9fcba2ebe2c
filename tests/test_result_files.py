"""Result files: written whole, and resumed only by a call that wrote them."""

import json

import pytest

from mfsample._json import read_resumable_rows, write_json


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
