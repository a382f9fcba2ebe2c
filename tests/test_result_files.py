"""Result files: JSON written whole or not at all."""

import json

from mfsample._json import write_json


def test_write_json_leaves_no_temporary_file_and_makes_its_folder(tmp_path):
  path = tmp_path / "new" / "out.json"
  write_json(str(path), {"a": [1, 2]})
  assert json.loads(path.read_text()) == {"a": [1, 2]}
  assert [p.name for p in path.parent.iterdir()] == ["out.json"]
