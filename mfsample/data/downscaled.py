"""Downscaled image folders (`images_N/`) made from a capture's own images when missing.

COLMAP, LLFF and nerfstudio captures keep smaller copies of their photographs in
`images_N/` (1/N of the size, the same file names), and the loaders read them for
`factor=N`. Not every tool writes them: `colmap image_undistorter` writes `images/` only.
When `images_N/` is missing, the loaders make it here, beside `images/`, once: every image
is resized to (W / N, H / N) rounded with a Lanczos filter, as 3DGS's `convert.py`
has ImageMagick do (`mogrify -resize`, whose filter for shrinking is Lanczos), on the
straight colour premultiplied by alpha where the image has one. The file names and formats
are kept (PNGs of 8 or 16 bits as their source; JPEGs at quality 95). A log line says so.

The folder is written under a temporary name and renamed when complete, so an interrupted
run leaves no partial `images_N/` that a later run would read as the capture's. The
loaders scale the intrinsics by the size of the images they find, so a size rounded to
whole pixels is read exactly as a folder made by another tool.
"""

import logging
import os
import shutil
from pathlib import Path

import numpy as np
from PIL import Image

from mfsample.data import _io

_LOG = logging.getLogger(__name__)
_RESAMPLING = getattr(Image, "Resampling", Image)  # Pillow < 9.1 has the names on Image
JPEG_QUALITY = 95


class MissingImageFolder(FileNotFoundError):
  """`images_N/` is missing and could not be made (the message names the folders found)."""


def downscaled_size(width, height, factor):
  """(width, height) of a 1 / `factor` copy: each side rounded half up, at least one pixel."""
  return max(1, int(width / factor + 0.5)), max(1, int(height / factor + 0.5))


def folder_name(factor):
  """The image folder of a factor: `images` for 1, `images_N` otherwise."""
  return "images" if factor == 1 else f"images_{int(factor)}"


def image_folder(root, factor, sources, *, make=True, source_folder="images"):
  """The `images_{factor}/` folder of a capture, written from `sources` if it is missing.

  Args:
    root: the capture folder.
    factor: integer >= 2 (factor 1 is the capture's own `images/`, never written here).
    sources: callable returning [(source image file, path under the new folder)], called only
      when the folder has to be made (the images the capture's model uses).
    make: write a missing folder (False: refuse it).
    source_folder: the folder under `root` that the sources are in, checked first (None:
      the sources are anywhere).

  Returns:
    the folder (`root / images_{factor}`).

  Raises:
    MissingImageFolder: the folder is missing and `make` is False, or it cannot be written
      (a read-only capture); the message names the image folders found.
    FileNotFoundError, DatasetError: a source image is missing or unreadable (named).
  """
  root = Path(root)
  folder = root / folder_name(factor)
  if folder.is_dir():
    return folder
  found = sorted(p.name for p in root.glob("images*") if p.is_dir())
  missing = (f"image folder for factor={factor} not found: {folder} (image folders in "
             f"{root}: {', '.join(found) or 'none'})")
  if not make:
    raise MissingImageFolder(f"{missing}.")
  if source_folder is not None and not (root / source_folder).is_dir():
    raise MissingImageFolder(f"{missing}, nor {source_folder}/ to make it from.")
  pairs = list(sources())
  partial = root / f".{folder.name}.partial-{os.getpid()}"
  try:
    for source, name in pairs:
      pixels = downscaled_pixels(source, factor)  # a missing or bad image: named, as it is
      try:
        save_pixels(pixels, partial / name, sixteen=_is_16_bit(source))
      except OSError as e:
        raise MissingImageFolder(f"{missing}, and it cannot be written there "
                                 f"({e.strerror or e}: {e.filename or partial}); make it, or "
                                 "read another factor.") from e
    try:
      os.rename(partial, folder)
    except OSError:
      if not folder.is_dir():  # (another process may have finished it first: use theirs)
        raise
  finally:
    shutil.rmtree(partial, ignore_errors=True)
  _LOG.warning("%s: made %s/ from the %d images of the capture, each downscaled %dx (Lanczos); "
               "later runs read it as it is", root, folder.name, len(pairs), factor)
  return folder


def downscaled_pixels(source, factor):
  """[h, w, 3 or 4] float in [0, 1]: the image file `source` resized by 1 / `factor`
  (Lanczos on the colour premultiplied by alpha; the straight colour, then alpha, out)."""
  colour, alpha = _io.read_image(source)
  height, width = colour.shape[:2]
  size = downscaled_size(width, height, factor)
  if alpha is None:
    return np.clip(_resize(colour, size), 0.0, 1.0)  # (Lanczos rings past the range)
  small_alpha = np.clip(_resize(alpha, size), 0.0, 1.0)
  premultiplied = _resize(colour * alpha[..., None], size)
  colour = np.where(small_alpha[..., None] > 0,
                    premultiplied / np.maximum(small_alpha[..., None], 1e-12), 0.0)
  return np.concatenate([np.clip(colour, 0.0, 1.0), small_alpha[..., None]], axis=-1)


def save_pixels(pixels, target, *, sixteen=False):
  """Writes [h, w, 3 or 4] floats in [0, 1] to `target` in the format of its suffix: PNG
  (16 bits per channel when `sixteen`, else 8) or JPEG (RGB, quality `JPEG_QUALITY`)."""
  target = Path(target)
  target.parent.mkdir(parents=True, exist_ok=True)
  if sixteen and target.suffix.lower() == ".png":
    import png

    data = np.round(pixels * 65535.0).astype(np.uint16)
    h, w, c = data.shape
    with open(target, "wb") as f:
      png.Writer(w, h, greyscale=False, alpha=c == 4, bitdepth=16).write(
          f, data.reshape(h, w * c))
    return target
  image = Image.fromarray(np.round(pixels * 255.0).astype(np.uint8))
  if target.suffix.lower() in (".jpg", ".jpeg"):
    image = image.convert("RGB")
    image.save(target, quality=JPEG_QUALITY)
  else:
    image.save(target)
  return target


def _is_16_bit(path):
  return Path(path).suffix.lower() == ".png" and _io.png_bit_depth(path) == 16


def _resize(x, size):
  """[H, W] or [H, W, C] float resized to `size` (width, height), channel by channel."""
  if x.ndim == 2:
    return np.asarray(Image.fromarray(np.ascontiguousarray(x, np.float32)).resize(
        size, _RESAMPLING.LANCZOS), np.float32)
  return np.stack([_resize(x[..., c], size) for c in range(x.shape[-1])], axis=-1)
