"""Any 3DGS .ply rendered to PNG: its Gaussians, or their uncertainty (docs/your_data.md).

  python experiments/render_ply.py --ply=output/scene/point_cloud/iteration_30000/point_cloud.ply \
      --up=0,-1,0 --out=model.png
  python experiments/render_ply.py --ply=workdirs/scene/uncertainty_ply/model_colours.ply \
      --colour_by=u_share --properties=workdirs/scene/uncertainty_ply/per_gaussian.ply \
      --cameras=workdirs/scene/next_views/cameras.json --out=share.png

Renders from an orbit around the Gaussians (--views, --elevation, --up, --size) or from the
cameras of a 3DGS cameras.json (--cameras, --scale), the views side by side in one PNG.
"""

import sys

from absl import app, flags

_PLY = flags.DEFINE_string("ply", None, "A .ply in the 3DGS layout.")
_OUT = flags.DEFINE_string("out", None, "The PNG to write.")
_COLOUR_BY = flags.DEFINE_string("colour_by", None, "Colour every Gaussian by this float "
                                 "property (magma, top at the 99th percentile): u_share, "
                                 "position_std, colour_std of the next-views job, or any of "
                                 "the file's. Default: the Gaussians' own colours.")
_PROPERTIES = flags.DEFINE_string("properties", None, "The .ply holding --colour_by, one row "
                                  "per Gaussian of --ply (the job's per_gaussian.ply); "
                                  "default: --ply itself.")
_CAMERAS = flags.DEFINE_string("cameras", None, "A 3DGS cameras.json (the reference code's "
                               "model folder, the job's next_views/): render from its cameras "
                               "instead of an orbit.")
_SCALE = flags.DEFINE_float("scale", 1.0, "With --cameras: scale their image size by this.")
_FIRST = flags.DEFINE_integer("first", 8, "With --cameras: render at most this many of them.")
_VIEWS = flags.DEFINE_integer("views", 4, "Orbit: number of views around the Gaussians.")
_ELEVATION = flags.DEFINE_float("elevation", 20.0, "Orbit: elevation in degrees.")
_UP = flags.DEFINE_list("up", ["0", "0", "1"], "Orbit: the scene's up direction (COLMAP "
                        "worlds are often 0,-1,0).")
_SIZE = flags.DEFINE_list("size", ["320", "240"], "Orbit: width,height of each view.")
_BACKGROUND = flags.DEFINE_list("background", ["0", "0", "0"], "Background colour, 0-1.")
flags.mark_flags_as_required(["ply", "out"])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
  import imageio.v3 as iio
  import numpy as np

  from mfsample.data import DatasetError, load_ply
  from mfsample.your_data.render_ply import inria_camera_list, orbit_around, render_ply, tile

  try:
    numbers = lambda values, flag: [float(v) for v in values] if all(
        _is_number(v) for v in values) else sys.exit(f"error: --{flag} takes numbers, got "
                                                     f"{','.join(values)}")
    if _CAMERAS.value:
      cameras, _ = inria_camera_list(_CAMERAS.value, scale=_SCALE.value)
      cameras = cameras[:max(1, _FIRST.value)]
    else:
      width, height = (int(v) for v in numbers(_SIZE.value, "size"))
      cameras = orbit_around(load_ply(_PLY.value)["means"], _VIEWS.value, width=width,
                             height=height, elevation_deg=_ELEVATION.value,
                             up=numbers(_UP.value, "up"))
    images = render_ply(_PLY.value, cameras, colour_by=_COLOUR_BY.value,
                        properties=_PROPERTIES.value,
                        background=numbers(_BACKGROUND.value, "background"))
  except (DatasetError, FileNotFoundError, ValueError) as e:
    sys.exit(f"error: {e}")
  iio.imwrite(_OUT.value, np.round(tile(images) * 255.0).astype(np.uint8))
  print(f"wrote {_OUT.value}: {len(images)} view(s) of {_PLY.value}")


def _is_number(text):
  try:
    float(text)
  except ValueError:
    return False
  return True


if __name__ == "__main__":
  app.run(main)
