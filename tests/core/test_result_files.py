"""Result files: JSON written whole or not at all."""

import json

from mfsample._json import write_json


def test_write_json_leaves_no_temporary_file_and_makes_its_folder(tmp_path):
  path = tmp_path / "new" / "out.json"
  write_json(str(path), {"a": [1, 2]})
  assert json.loads(path.read_text()) == {"a": [1, 2]}
  assert [p.name for p in path.parent.iterdir()] == ["out.json"]


def test_a_failed_write_names_the_file_and_leaves_no_temporary(tmp_path):
  import errno

  import pytest

  from mfsample._json import atomic_path

  path = tmp_path / "out" / "table.md"
  with pytest.raises(OSError, match=r"cannot write .*out/table\.md: No space left") as e:
    with atomic_path(path) as tmp:
      with open(tmp, "w") as f:
        f.write("half a table")
      raise OSError(errno.ENOSPC, "No space left on device")  # as a full disk would
  assert e.value.errno == errno.ENOSPC and e.value.filename == str(path)
  assert list((tmp_path / "out").iterdir()) == []


def test_temporary_names_are_unique_and_keep_the_extension(tmp_path):
  from mfsample._json import atomic_path

  with atomic_path(tmp_path / "a.png") as one, atomic_path(tmp_path / "a.png") as two:
    assert one != two and one.endswith(".png") and two.endswith(".png")
    for t in (one, two):
      with open(t, "w") as f:
        f.write(t)


def test_write_json_writes_undefined_numbers_as_null(tmp_path):
  """Standard JSON: NaN and infinities (Python or numpy) become null, never bare NaN."""
  import numpy as np

  path = tmp_path / "out.json"
  write_json(str(path), {"rho": float("nan"), "u": [1.5, np.float32("inf"), -np.inf],
                         "nested": ({"x": np.float64("nan"), "n": np.int64(3)},),
                         "ok": np.float32(0.25), "text": "nan"})
  text = path.read_text()
  assert "NaN" not in text and "Infinity" not in text
  assert json.loads(text) == {"rho": None, "u": [1.5, None, None],
                              "nested": [{"x": None, "n": 3}], "ok": 0.25, "text": "nan"}


def test_result_files_get_the_permissions_of_any_new_file(tmp_path):
  import os

  from mfsample._json import write_json

  mask = os.umask(0o022)
  try:
    write_json(str(tmp_path / "a.json"), {})
  finally:
    os.umask(mask)
  # 0644 under the usual umask 022 (the module reads the umask at import: 022 in CI too).
  assert (tmp_path / "a.json").stat().st_mode & 0o777 == 0o666 & ~_json_umask()


def _json_umask():
  from mfsample import _json

  return _json._UMASK
