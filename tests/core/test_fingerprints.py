"""Fingerprints of files and folders, and the record of the files a loader reads."""

import os

import numpy as np
import pytest

from mfsample import fingerprints


def _touch_later(path, seconds=10):
  st = os.stat(path)
  os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + seconds * 10**9))


def test_a_small_file_is_the_same_while_its_bytes_are(tmp_path):
  path = tmp_path / "transforms.json"
  path.write_bytes(b'{"frames": [1, 2]}')
  old = fingerprints.fingerprint(path)
  assert old["kind"] == "file" and old["size"] == 18 and "edges_sha256" not in old
  assert fingerprints.change(path, old) == ""
  _touch_later(path)  # a copy of the same bytes, with a new time, is the same file
  assert fingerprints.change(path, old) == ""
  mtime = old["mtime_ns"]
  path.write_bytes(b'{"frames": [1, 3]}')  # same size, same time: the hash tells
  os.utime(path, ns=(mtime, mtime))
  what = fingerprints.change(path, old)
  assert what.startswith("sha256 ") and "size" not in what
  path.write_bytes(b'{"frames": [1]}')
  assert "size 18 -> 15 bytes" in fingerprints.change(path, old)
  path.unlink()
  assert fingerprints.change(path, old) == "removed"
  path.mkdir()
  assert fingerprints.change(path, old) == "no longer a file"
  assert fingerprints.fingerprint(tmp_path / "none") == {"kind": "missing"}


def test_a_large_file_is_compared_by_its_ends_while_size_and_time_match(tmp_path, monkeypatch):
  monkeypatch.setattr(fingerprints, "SMALL", 64)
  monkeypatch.setattr(fingerprints, "EDGE", 16)
  path = tmp_path / "model.ply"
  data = bytearray(np.arange(200, dtype=np.uint8).tobytes())
  path.write_bytes(bytes(data))
  old = fingerprints.fingerprint(path)
  assert "edges_sha256" in old
  mtime = os.stat(path).st_mtime_ns

  def rewrite(new, keep_time):
    path.write_bytes(bytes(new))
    if keep_time:
      os.utime(path, ns=(mtime, mtime))

  middle = bytearray(data)
  middle[100] ^= 1
  rewrite(middle, keep_time=True)  # the one change not seen (documented)
  assert fingerprints.change(path, old) == ""
  rewrite(middle, keep_time=False)  # another time: hashed whole
  assert "sha256" in fingerprints.change(path, old)
  end = bytearray(data)
  end[-1] ^= 1
  rewrite(end, keep_time=True)
  assert "sha256" in fingerprints.change(path, old)
  rewrite(data, keep_time=False)  # the same bytes again, a new time
  assert fingerprints.change(path, old) == ""


def test_a_folder_is_its_listing(tmp_path):
  (tmp_path / "a.png").write_bytes(b"a")
  old = fingerprints.fingerprint(tmp_path)
  assert old == {"kind": "folder", "names": ["a.png"]}
  (tmp_path / "a.png").write_bytes(b"changed")  # contents are the files' own records
  assert fingerprints.change(tmp_path, old) == ""
  (tmp_path / "b.png").write_bytes(b"b")
  assert fingerprints.change(tmp_path, old) == "entries added b.png"
  (tmp_path / "a.png").unlink()
  assert fingerprints.change(tmp_path, old) == "entries added b.png; removed a.png"


def test_changes_name_every_changed_entry(tmp_path):
  a, b = tmp_path / "a", tmp_path / "b"
  a.write_text("x")
  b.write_text("y")
  record = {str(a): fingerprints.fingerprint(a), str(b): fingerprints.fingerprint(b)}
  assert fingerprints.changes(record) == []
  b.write_text("yy")
  a.unlink()
  first, second = fingerprints.changes(record)
  assert first == f"{a}: removed" and second.startswith(f"{b}: size 1 -> 2 bytes, modified ")
  assert fingerprints.changes({str(b): "garbage"}) == [f"{b}: unreadable record"]


def test_files_under_lists_every_file_of_folders(tmp_path):
  (tmp_path / "d" / "e").mkdir(parents=True)
  (tmp_path / "d" / "e" / "x.json").write_text("1")
  (tmp_path / "r.json").write_text("2")
  files = fingerprints.files_under(tmp_path, ["d", "r.json", "absent.png"])
  assert list(files) == [os.path.join("d", "e", "x.json"), "r.json"]


def test_a_recording_collects_what_is_announced_and_nothing_outside(tmp_path):
  path = tmp_path / "a.json"
  path.write_text("{}")
  fingerprints.note(path)  # no recording: nothing happens
  seen = []
  with fingerprints.recording() as outer:
    outer.on_new = lambda p, fp: seen.append(p)
    with fingerprints.recording() as inner:
      fingerprints.note(path)
      fingerprints.note(path)  # once
      fingerprints.note(tmp_path / "missing.json")  # the reader reports it
    fingerprints.note(tmp_path)
  fingerprints.note(path)
  assert list(inner.files) == [str(path)]
  assert list(outer.files) == [str(path), str(tmp_path)] and seen == list(outer.files)


@pytest.mark.parametrize("kind", ["colmap", "nerfstudio", "blender", "llff"])
def test_the_loaders_announce_every_file_they_read(kind, tmp_path):
  """Whatever the kind, each file the loader reads is recorded, and a changed image and a
  changed camera file are found by `changes`."""
  from mfsample import testing
  from mfsample.data import PointCloud, datasets, export_colmap, export_nerfstudio
  from mfsample.data.export import export_blender

  views, _ = testing.synthetic_views(4, size=32)
  root = tmp_path / "capture"
  xyz = np.zeros((3, 3))
  if kind == "colmap":
    export_colmap(root, views, PointCloud(xyz, np.full_like(xyz, 0.5)))
  elif kind == "nerfstudio":
    export_nerfstudio(root, views, PointCloud(xyz, np.full_like(xyz, 0.5)))
  elif kind == "blender":
    export_blender(root, views, split="train")
    export_blender(root, views, split="test")
  else:
    _export_llff(root, views)
  spec = datasets.DataSpec(kind=kind, path=str(root), holdout_every=2)
  with fingerprints.recording() as rec:
    datasets.load_dataset(spec)
  files = [p for p, fp in rec.files.items() if fp["kind"] == "file"]
  images = [p for p in files if p.endswith(".png")]
  assert len(images) >= len(views), sorted(rec.files)
  assert len(files) > len(images)  # and the cameras' files
  assert set(files) <= {str(p) for p in root.rglob("*") if p.is_file()}
  assert fingerprints.changes(rec.files) == []
  camera_file = sorted(set(files) - set(images))[0]
  with open(camera_file, "ab") as f:
    f.write(b" ")
  with open(images[1], "r+b") as f:
    f.seek(os.path.getsize(images[1]) // 2)
    f.write(b"\x00\x01")
  changed = [c.split(": ")[0] for c in fingerprints.changes(rec.files)]
  assert sorted(changed) == sorted([camera_file, images[1]])


def _export_llff(root, views):
  """An LLFF folder of `views`: poses_bounds.npy and images/."""
  from PIL import Image

  from mfsample.data import poses_bounds_from_cameras

  (root / "images").mkdir(parents=True)
  for i, image in enumerate(np.asarray(views.images)):
    Image.fromarray(np.round(image * 255).astype(np.uint8)).save(root / "images" / f"{i}.png")
  bounds = np.tile([1.0, 6.0], (len(views), 1))
  np.save(root / "poses_bounds.npy", poses_bounds_from_cameras(views.cameras, bounds))
