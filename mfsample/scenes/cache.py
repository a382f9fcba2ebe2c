"""On-disk cache of captures: one `.npz` per (what, scene, camera, resolution, spp, variant).

Keys hash everything that determines the pixels (the scene's fingerprint, the camera rounded
to 1e-6, the image size, spp, the Mitsuba variant, the capture kind and its settings), so a
cache entry never goes stale silently. Writes are atomic (a temporary file in the same folder,
then `os.replace`): a killed run loses at most the capture in progress and never leaves a
truncated file behind. Reading needs neither Mitsuba nor the renderer.
"""

import hashlib
import json
import os
import tempfile
import warnings
import zipfile
from pathlib import Path

import numpy as np

CACHE_ENV = "MFSAMPLE_CACHE"

# Bump when the capture code changes its output for the same inputs.
CAPTURE_VERSION = 1


def default_cache_dir():
  """$MFSAMPLE_CACHE, else $XDG_CACHE_HOME/mfsample/captures (~/.cache/mfsample/captures)."""
  if os.environ.get(CACHE_ENV):
    return Path(os.environ[CACHE_ENV]).expanduser()
  base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
  return Path(base) / "mfsample" / "captures"


def camera_record(camera):
  """A json-able, rounding-stable description of one camera."""
  def rounded(x):
    # + 0.0 turns -0.0 into 0.0, so that both hash alike.
    return (np.round(np.asarray(x, np.float64), 6) + 0.0).tolist()

  return {"world_to_camera": rounded(camera.world_to_camera), "fx": rounded(camera.fx),
          "fy": rounded(camera.fy), "cx": rounded(camera.cx), "cy": rounded(camera.cy),
          "width": int(camera.width), "height": int(camera.height)}


def capture_key(kind, scene, camera, *, spp, variant, **settings):
  """Hex key of one capture.

  Args:
    kind: what is captured ("rgbad": radiance, alpha, depth; "sh_basis").
    scene: a `Scene` (its fingerprint enters the key).
    camera: one unbatched `Camera`.
    spp: samples per pixel.
    variant: Mitsuba variant name.
    **settings: anything else that changes the pixels (e.g. degree, envmap size).
  """
  payload = {"kind": kind, "scene": scene.name, "fingerprint": scene.fingerprint(),
             "camera": camera_record(camera), "spp": int(spp), "variant": variant,
             "version": CAPTURE_VERSION, "settings": settings}
  return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def entry_path(cache_dir, scene, kind, key):
  return Path(cache_dir) / scene.name / f"{kind}-{key[:32]}.npz"


def load(path, expected=None):
  """The arrays stored at `path` as a dict, or None when absent or unusable.

  An unusable entry (unreadable, or - when `expected` = {name: shape} is given - missing an
  array, of another shape, or not finite) is reported with a warning naming the file and
  treated as absent, so the caller recomputes and overwrites it.
  """
  path = Path(path)
  if not path.is_file():
    return None
  try:
    with np.load(path, allow_pickle=False) as data:
      arrays = {k: data[k] for k in data.files}
  except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
    # Only a file written by other means can be corrupt (ours are atomic): recompute it.
    warnings.warn(f"ignoring unreadable cache entry {path}: {e}", stacklevel=2)
    return None
  for name, shape in (expected or {}).items():
    value = arrays.get(name)
    problem = ("has no array " + repr(name) if value is None
               else f"{name} has shape {value.shape}, expected {tuple(shape)}"
               if value.shape != tuple(shape)
               else f"{name} has non-finite values" if not np.all(np.isfinite(value))
               else None)
    if problem:
      warnings.warn(f"ignoring unusable cache entry {path}: {problem}", stacklevel=2)
      return None
  return arrays


def save(path, arrays):
  """Writes `arrays` (name -> numpy array) to `path` atomically."""
  path = Path(path)
  path.parent.mkdir(parents=True, exist_ok=True)
  fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp")
  try:
    with os.fdopen(fd, "wb") as f:
      np.savez(f, **arrays)
      f.flush()
      os.fsync(f.fileno())
    os.replace(tmp, path)
  except BaseException:
    Path(tmp).unlink(missing_ok=True)
    raise
