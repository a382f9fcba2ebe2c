"""Any 3DGS .ply rendered to PNG: `mfsample render-ply --ply=FILE --out=PNG`
(`experiments/render_ply.py`; docs/your_data.md).

  mfsample render-ply --ply=output/scene/point_cloud/iteration_30000/point_cloud.ply \
      --up=0,-1,0 --out=model.png
  mfsample render-ply --ply=workdirs/scene/uncertainty_ply/model_colours.ply \
      --colour_by=u_share --properties=workdirs/scene/uncertainty_ply/per_gaussian.ply \
      --cameras=workdirs/scene/next_views/cameras.json --out=share.png

Renders from an orbit around the Gaussians (--views, --elevation, --up, --size) or from the
cameras of a 3DGS cameras.json (--cameras, --scale), the views side by side in one PNG.
Errors are one line and exit code 1.
"""

import sys


def main():
  """The absl entry point: defines the command's flags and writes the PNG."""
  from absl import app, flags

  ply = flags.DEFINE_string("ply", None, "A .ply in the 3DGS layout.")
  out = flags.DEFINE_string("out", None, "The PNG to write.")
  colour_by = flags.DEFINE_string(
      "colour_by", None, "Colour every Gaussian by this float property (magma, top at the "
      "99th percentile): u_share, position_std, colour_std of the next-views job, or any of "
      "the file's. Default: the Gaussians' own colours.")
  properties = flags.DEFINE_string(
      "properties", None, "The .ply holding --colour_by, one row per Gaussian of --ply (the "
      "job's per_gaussian.ply); default: --ply itself.")
  cameras_flag = flags.DEFINE_string(
      "cameras", None, "A 3DGS cameras.json (the reference code's model folder, the job's "
      "next_views/): render from its cameras instead of an orbit.")
  scale = flags.DEFINE_float("scale", 1.0, "With --cameras: scale their image size by this.")
  first = flags.DEFINE_integer("first", 8, "With --cameras: render at most this many of them.")
  views = flags.DEFINE_integer("views", 4, "Orbit: number of views around the Gaussians.")
  elevation = flags.DEFINE_float("elevation", 20.0, "Orbit: elevation in degrees.")
  up = flags.DEFINE_list("up", ["0", "0", "1"], "Orbit: the scene's up direction (COLMAP "
                         "worlds are often 0,-1,0).")
  size = flags.DEFINE_list("size", ["320", "240"], "Orbit: width,height of each view.")
  background = flags.DEFINE_list("background", ["0", "0", "0"], "Background colour, 0-1.")
  flags.mark_flags_as_required(["ply", "out"])

  def run(argv):
    if len(argv) > 1:
      raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
    import imageio.v3 as iio
    import numpy as np

    from mfsample.data import DatasetError, load_ply
    from mfsample.your_data.render_ply import inria_camera_list, orbit_around, render_ply, tile

    def numbers(values, flag):
      if not all(_is_number(v) for v in values):
        sys.exit(f"error: --{flag} takes numbers, got {','.join(values)}")
      return [float(v) for v in values]

    try:
      if cameras_flag.value:
        cameras, _ = inria_camera_list(cameras_flag.value, scale=scale.value)
        cameras = cameras[:max(1, first.value)]
      else:
        width, height = (int(v) for v in numbers(size.value, "size"))
        cameras = orbit_around(load_ply(ply.value)["means"], views.value, width=width,
                               height=height, elevation_deg=elevation.value,
                               up=numbers(up.value, "up"))
      images = render_ply(ply.value, cameras, colour_by=colour_by.value,
                          properties=properties.value,
                          background=numbers(background.value, "background"))
    except (DatasetError, FileNotFoundError, ValueError) as e:
      sys.exit(f"error: {e}")
    iio.imwrite(out.value, np.round(tile(images) * 255.0).astype(np.uint8))
    print(f"wrote {out.value}: {len(images)} view(s) of {ply.value}")

  app.run(run)


def _is_number(text):
  try:
    float(text)
  except ValueError:
    return False
  return True
