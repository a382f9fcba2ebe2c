"""What a file was: fingerprints, their comparison, and the record of the files a run reads.

A job's results depend on the files it read (a capture's `transforms.json`, its COLMAP
model and images, a `.ply` it starts from or fits B_hat to) and point to the files it wrote.
Both are kept as fingerprints, so that a later call can tell whether they are still what
they were:

* a loader announces every file before it reads it (`note(path)`; a folder whose listing it
  reads, `note(folder)`), and a job collects the announcements of its run (`recording()`);
  the workdir keeps them (`mfsample.jobs`: `inputs.json`);
* `changes(record)` lists, one line each, the entries of a record that are no longer what
  they were (removed, or another size, time and content).

A file's fingerprint is its size, its modification time (ns) and the SHA-256 of its content;
one over `SMALL` bytes also keeps the SHA-256 of its first and last `EDGE` bytes. A file is
unchanged when its content is: equal SHA-256 (a copy of the same bytes, with a new time, is
the same file). Small files are hashed whole at every comparison. A large one whose size,
time and head-and-tail hash all match its record is taken as unchanged without reading it
whole (as `git status` trusts a file whose size and time match its index); otherwise it is
hashed whole. So a change inside a file over `SMALL` bytes that keeps its size, its time
and its first and last `EDGE` bytes is the one change not seen. A folder's fingerprint is
the sorted names of its entries.
"""

import contextlib
import contextvars
import datetime
import hashlib
import os

SMALL = 4 << 20  # Files up to 4 MiB are hashed whole at every comparison.
EDGE = 1 << 20  # Larger ones are first compared by their first and last MiB.
_BLOCK = 1 << 20


def _sha256(path, ranges=None):
  """SHA-256 (hex) of the file's content, or of the byte `ranges` [(start, length)]."""
  h = hashlib.sha256()
  with open(path, "rb") as f:
    for start, length in ranges or [(0, None)]:
      f.seek(start)
      left = length
      while left is None or left > 0:
        block = f.read(_BLOCK if left is None else min(_BLOCK, left))
        if not block:
          break
        h.update(block)
        if left is not None:
          left -= len(block)
  return h.hexdigest()


def _edges(path, size):
  return _sha256(path, [(0, EDGE), (max(size - EDGE, EDGE), EDGE)])


def fingerprint(path):
  """The fingerprint (a JSON dict) of a file or folder; {"kind": "missing"} when neither.

  A file: {"kind": "file", "size", "mtime_ns", "sha256"} (+ "edges_sha256": first and last
  `EDGE` bytes, over `SMALL` bytes); a folder: {"kind": "folder", "names": sorted entries}.

  Raises:
    OSError: the file exists but cannot be read.
  """
  path = os.fspath(path)
  if os.path.isdir(path):
    return {"kind": "folder", "names": sorted(os.listdir(path))}
  if not os.path.isfile(path):
    return {"kind": "missing"}
  st = os.stat(path)
  out = {"kind": "file", "size": st.st_size, "mtime_ns": st.st_mtime_ns,
         "sha256": _sha256(path)}
  if st.st_size > SMALL:
    out["edges_sha256"] = _edges(path, st.st_size)
  return out


def _times(old_ns, new_ns):
  """"old -> new" modification times, to the second (finer where the seconds agree)."""
  for spec in ("seconds", "microseconds"):
    old, new = (datetime.datetime.fromtimestamp(t / 1e9).isoformat(sep=" ", timespec=spec)
                for t in (old_ns, new_ns))
    if old != new:
      break
  return f"{old} -> {new}"


def change(path, old):
  """What changed in the file or folder `path` since its fingerprint `old`: "" when
  nothing, else a short text ("size 120 -> 96 bytes, modified ... -> ..., sha256 ...")."""
  path = os.fspath(path)
  kind = old.get("kind")
  if kind == "folder":
    if not os.path.isdir(path):
      return "removed" if not os.path.exists(path) else "no longer a folder"
    names, was = set(os.listdir(path)), set(old.get("names", ()))
    if names == was:
      return ""
    parts = [f"{label} {', '.join(sorted(s)[:5])}{' ...' if len(s) > 5 else ''}"
             for label, s in (("added", names - was), ("removed", was - names)) if s]
    return "entries " + "; ".join(parts)
  if not os.path.isfile(path):
    return "removed" if not os.path.exists(path) else "no longer a file"
  try:
    st = os.stat(path)
    if (st.st_size == old.get("size") and st.st_size > SMALL
        and st.st_mtime_ns == old.get("mtime_ns")
        and _edges(path, st.st_size) == old.get("edges_sha256")):
      return ""
    new = {"size": st.st_size, "mtime_ns": st.st_mtime_ns}
    if st.st_size == old.get("size"):  # (another size: changed, whatever its content)
      new["sha256"] = _sha256(path)
      if new["sha256"] == old.get("sha256"):
        return ""
  except OSError as e:
    return f"unreadable ({e.strerror})"
  parts = []
  if new["size"] != old.get("size"):
    parts.append(f"size {old.get('size')} -> {new['size']} bytes")
  if new["mtime_ns"] != old.get("mtime_ns") and isinstance(old.get("mtime_ns"), int):
    parts.append(f"modified {_times(old['mtime_ns'], new['mtime_ns'])}")
  if "sha256" in new:
    parts.append(f"sha256 {str(old.get('sha256'))[:12]} -> {new['sha256'][:12]}")
  return ", ".join(parts)


def changes(record):
  """["path: what changed", ...] of the entries of `record` ({path: fingerprint}) that are no
  longer what they were, in the record's order."""
  out = []
  for path, old in record.items():
    what = change(path, old) if isinstance(old, dict) else "unreadable record"
    if what:
      out.append(f"{path}: {what}")
  return out


def files_under(root, names):
  """{path relative to `root`: fingerprint} of the files `names` (relative to `root`) and
  of every file under the folders among them (names of nothing are left out)."""
  out = {}
  for name in names:
    path = os.path.join(root, name)
    if os.path.isdir(path):
      for folder, _, files in os.walk(path):
        for file in files:
          full = os.path.join(folder, file)
          out[os.path.relpath(full, root)] = fingerprint(full)
    elif os.path.isfile(path):
      out[os.path.normpath(name)] = fingerprint(path)
  return dict(sorted(out.items()))


# ------------------------------------------------------------------ the files a run reads


class Recording:
  """The fingerprints of the files announced (`note`) while it is active: {path: fingerprint}
  in `files`, absolute paths; `on_new(path, fingerprint)` is called for each new one."""

  def __init__(self):
    self.files = {}
    self.on_new = None

  def add(self, path):
    path = os.path.abspath(os.fspath(path))
    if path in self.files:
      return
    try:
      fp = fingerprint(path)
    except OSError:  # unreadable: the reader that announced it reports that
      return
    if fp["kind"] == "missing":  # likewise
      return
    self.files[path] = fp
    if self.on_new is not None:
      self.on_new(path, fp)


_ACTIVE = contextvars.ContextVar("mfsample_fingerprints_recordings", default=())


@contextlib.contextmanager
def recording():
  """Collects the fingerprints of the files announced by `note` in the block (nested
  recordings each get them all)."""
  rec = Recording()
  token = _ACTIVE.set(_ACTIVE.get() + (rec,))
  try:
    yield rec
  finally:
    _ACTIVE.reset(token)


def note(path):
  """Announces that the file (or folder listing) at `path` is about to be read as an input:
  the active recordings take its fingerprint. Does nothing outside a recording."""
  for rec in _ACTIVE.get():
    rec.add(path)
