"""A capture without the asked `images_N/` gets one, made once from its own images."""

import logging
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image

from mfsample.data import (
  DatasetError,
  downscaled,
  export_nerfstudio,
  load_llff,
  load_nerfstudio,
  poses_bounds_from_cameras,
)
from mfsample.data.datasets import DataSpec, load_dataset
from mfsample.testing import synthetic_views, write_tiny_capture

pycolmap = pytest.importorskip("pycolmap")

LOG = "mfsample.data.downscaled"


def _lanczos(file, factor):
  """The reference: Pillow's own Lanczos resize of the 8-bit RGB file, 8 bits out."""
  with Image.open(file) as image:
    w, h = image.size
    small = image.convert("RGB").resize(downscaled.downscaled_size(w, h, factor),
                                        Image.LANCZOS)
  return np.asarray(small, np.float32) / 255.0


@pytest.mark.parametrize("sparse", ["sparse", "sparse/0"])
def test_a_colmap_capture_without_images_n_gets_it_once(tmp_path, caplog, sparse):
  """The undistorter's layout (images/ and sparse/) and the mapper's (sparse/0)."""
  from mfsample.data import load_colmap

  capture, _ = write_tiny_capture(tmp_path, num_views=3, size=32, sparse=sparse)
  full, _ = load_colmap(capture)
  with caplog.at_level(logging.INFO, logger=LOG):
    views, _ = load_colmap(capture, factor=4)
  assert [r.getMessage() for r in caplog.records if r.name == LOG] == [
      f"{capture}: made images_4/ from the 3 images of the capture, each downscaled 4x "
      "(Lanczos); later runs read it as it is"]
  assert sorted(p.name for p in capture.iterdir()) == ["images", "images_4", "sparse"]
  assert views.images.shape == (3, 8, 8, 3)
  for k in ("fx", "fy", "cx", "cy"):  # intrinsics scaled exactly by the size
    np.testing.assert_allclose(getattr(views.cameras, k), getattr(full.cameras, k) / 4)
  files = sorted((capture / "images").iterdir())
  for i, file in enumerate(files):
    # (Pillow's 8-bit path rounds and clips between its two passes; floats here)
    np.testing.assert_allclose(views.images[i], _lanczos(file, 4), atol=5 / 255)
  # the colours stay those of the photographs (a 4x4 block mean, within Lanczos' ringing)
  blocks = full.images.reshape(3, 8, 4, 8, 4, 3).mean((2, 4))
  assert float(np.mean(np.abs(views.images - blocks))) < 0.03
  caplog.clear()
  stamp = (capture / "images_4" / files[0].name).stat().st_mtime_ns
  with caplog.at_level(logging.INFO, logger=LOG):
    again, _ = load_colmap(capture, factor=4)  # read as it is: not made again
  assert not [r for r in caplog.records if r.name == LOG]
  assert (capture / "images_4" / files[0].name).stat().st_mtime_ns == stamp
  np.testing.assert_array_equal(again.images, views.images)


def test_a_missing_folder_is_refused_in_one_line_when_not_made(tmp_path):
  from mfsample.data import load_colmap

  capture, _ = write_tiny_capture(tmp_path, num_views=2, size=16, sparse="sparse")
  with pytest.raises(downscaled.MissingImageFolder,
                     match=r"images_8 \(image folders in .*capture: images\)\.$"):
    load_colmap(capture, factor=8, make_downscaled=False)
  assert not (capture / "images_8").exists()


def test_a_capture_that_cannot_be_written_is_refused_naming_the_flag(tmp_path, monkeypatch):
  """A read-only capture: the one-line error names the folders found and the config field."""
  capture, _ = write_tiny_capture(tmp_path, num_views=2, size=16, sparse="sparse")

  def read_only(pixels, target, sixteen=False):
    raise PermissionError(13, "Permission denied", str(target))

  monkeypatch.setattr(downscaled, "save_pixels", read_only)
  spec = DataSpec(kind="colmap", path=str(capture), downscale=8)
  with pytest.raises(downscaled.MissingImageFolder) as info:
    load_dataset(spec)
  message = str(info.value)
  assert "\n" not in message and "image folders in" in message and ": images)" in message
  assert "cannot be written there (Permission denied" in message
  assert "config.data.downscale = 8" in message
  assert sorted(p.name for p in capture.iterdir()) == ["images", "sparse"]  # nothing left


def test_a_bad_image_leaves_no_partial_folder(tmp_path):
  """The folder appears whole or not at all: a later run never reads half of it."""
  from mfsample.data import load_colmap

  capture, _ = write_tiny_capture(tmp_path, num_views=3, size=16, sparse="sparse")
  last = sorted((capture / "images").iterdir())[-1]
  last.write_bytes(b"not an image")
  with pytest.raises(DatasetError, match=last.name):
    load_colmap(capture, factor=2)
  assert sorted(p.name for p in capture.iterdir()) == ["images", "sparse"]


def test_a_nerfstudio_capture_without_images_n_gets_it(tmp_path, caplog):
  views, _ = synthetic_views(3, size=16)
  export_nerfstudio(tmp_path / "ns", views)  # images/ only
  full, _ = load_nerfstudio(tmp_path / "ns")
  with caplog.at_level(logging.INFO, logger=LOG):
    small, _ = load_nerfstudio(tmp_path / "ns", factor=2)
  assert any("made images_2/ from the 3 images" in r.getMessage() for r in caplog.records)
  assert small.images.shape == (3, 8, 8, 3)
  np.testing.assert_allclose(small.cameras.fx, full.cameras.fx / 2)
  names = sorted(p.name for p in (tmp_path / "ns" / "images").iterdir())
  assert sorted(p.name for p in (tmp_path / "ns" / "images_2").iterdir()) == names


def test_an_llff_capture_without_images_n_gets_it(tmp_path):
  views, _ = synthetic_views(2, size=16)
  bounds = np.array([[1.0, 5.0], [1.0, 5.0]])
  np.save(tmp_path / "poses_bounds.npy", poses_bounds_from_cameras(views.cameras, bounds))
  (tmp_path / "images").mkdir()
  for i, image in enumerate(views.images):
    iio.imwrite(tmp_path / "images" / f"IMG_{i}.png", np.round(image * 255).astype(np.uint8))
  small, _ = load_llff(tmp_path, factor=2)
  assert small.images.shape == (2, 8, 8, 3) and small.names == ("IMG_0", "IMG_1")
  np.testing.assert_allclose(small.cameras.fx, np.asarray(views.cameras.fx) / 2, rtol=1e-6)


def test_alpha_and_16_bit_survive(tmp_path):
  """Colour under zero alpha does not bleed into its neighbours (premultiplied resampling);
  a 16-bit PNG stays 16-bit; odd sizes round half up."""
  rgba = np.zeros((9, 12, 4), np.uint16)
  rgba[..., 0] = 65535  # red, opaque on the left half
  rgba[:, :6, 3] = 65535
  rgba[:, 6:, 1] = 65535  # green where alpha is 0: must not show
  import png

  with open(tmp_path / "a.png", "wb") as f:
    png.Writer(12, 9, greyscale=False, alpha=True, bitdepth=16).write(f, rgba.reshape(9, -1))
  out = downscaled.save_pixels(downscaled.downscaled_pixels(tmp_path / "a.png", 2),
                               tmp_path / "b.png", sixteen=True)
  from mfsample.data._io import png_bit_depth, read_image

  assert png_bit_depth(out) == 16
  colour, alpha = read_image(out)
  assert colour.shape == (5, 6, 3)  # 4.5 -> 5, 6
  opaque = alpha > 0.5
  assert np.all(colour[opaque][:, 1] < 1e-3) and np.all(colour[opaque][:, 0] > 0.99)
  assert downscaled.downscaled_size(1, 1, 8) == (1, 1)


def test_a_jpeg_capture_keeps_its_names(tmp_path):
  (tmp_path / "images").mkdir()
  image = (np.random.default_rng(0).random((16, 16, 3)) * 255).astype(np.uint8)
  iio.imwrite(tmp_path / "images" / "a.jpg", image)
  folder = downscaled.image_folder(tmp_path, 2, lambda: [(tmp_path / "images" / "a.jpg",
                                                          "a.jpg")])
  assert folder == tmp_path / "images_2"
  with Image.open(folder / "a.jpg") as small:
    assert small.format == "JPEG" and small.size == (8, 8)
  assert Path(downscaled.folder_name(1)) == Path("images")
