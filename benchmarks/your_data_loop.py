"""The figure of docs/your_data.md's loop, from a tiny run of the your-data job.

  python benchmarks/your_data_loop.py --workdir=workdirs/your_data_loop

Writes a nerfstudio capture of random ground-truth Gaussians (12 views at 64 x 64, laid out
as ns-process-data lays out a capture), runs the your-data job on it (`data.kind =
"nerfstudio"`, a field trained on every 2nd of its 9 training views, the other 4 ranked by
U), and renders what
the viewers are given: the two .ply files of `uncertainty_ply/` seen from a test view (with
the project's renderer, as a splat viewer draws them), that view's U map, and the first
proposed view's preview from `next_views/`. About 6 minutes on two CPU cores; the figure
goes to `--out`.
"""

import json
import os

import numpy as np
from absl import app, flags

_WORKDIR = flags.DEFINE_string("workdir", "workdirs/your_data_loop", "Output folder.")
_OUT = flags.DEFINE_string("out", "docs/assets/your_data_loop.png", "Figure path (PNG).")


def loop_config(capture):
  """The your-data job's config for the tiny capture (every field else the default)."""
  from mfsample.your_data import default_config

  config = default_config()
  config.data.kind = "nerfstudio"
  config.data.path = str(capture)
  config.data.holdout_every = 4  # 3 test views, 9 for training and candidates
  config.data.background = (0.0, 0.0, 0.0)
  config.model.init_from = "points"
  config.model.sh_degree = 0
  config.model.max_gaussians = 2_000
  config.train.num_steps = 400
  config.train.progress = False
  config.densify.start = 100
  config.densify.stop = 300
  config.densify.opacity_reset_every = 10_000
  config.render.max_intersections = 1 << 14
  config.eval.save_images = 3
  config.views.train_every = 2
  config.next_views.k = 3
  return config


def write_capture(root):
  """12 views of 300 random Gaussians as a nerfstudio capture (ns-process-data's world)."""
  import jax.numpy as jnp

  from mfsample.data import PointCloud, export_nerfstudio
  from mfsample.data import synthetic as data_lib
  from mfsample.data.nerfstudio import NS_PROCESS_DATA_TRANSFORM

  gaussians = data_lib.synthetic_gaussians(300, seed=0)
  cameras = data_lib.orbit_cameras(12, 64, 64)
  views = data_lib.render_views(gaussians, cameras, (0.0, 0.0, 0.0))
  xyz = np.asarray(gaussians.means)
  colours = np.clip(np.asarray(gaussians.sh)[:, 0] * 0.28209479177387814 + 0.5, 0.0, 1.0)
  export_nerfstudio(root, views.replace(images=np.asarray(jnp.clip(views.images, 0, 1))),
                    PointCloud(xyz, colours), applied_transform=NS_PROCESS_DATA_TRANSFORM,
                    overwrite=True)


def figure(workdir, out):
  import imageio.v3 as iio
  import jax.numpy as jnp
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  from mfsample import render
  from mfsample.data import load_nerfstudio
  from mfsample.data.ply import load_ply
  from mfsample.model import activate
  from mfsample.renderer import RenderSettings
  from mfsample.renderer.budget import render_with_budget

  with open(os.path.join(workdir, "results.json")) as f:
    results = json.load(f)
  views, _ = load_nerfstudio(os.path.join(workdir, "..", "capture"))
  test = views.subset([0]).cameras[0]  # holdout_every = 4: view 0 is a test view
  settings = RenderSettings(max_intersections=1 << 14)

  def draw(ply):
    raw = load_ply(os.path.join(workdir, ply))
    gaussians = activate({g: jnp.asarray(v) for g, v in raw.items()}, None, 3)
    out, _ = render_with_budget(render, settings, gaussians, test, background=jnp.zeros(3))
    return np.clip(np.asarray(out.rgb), 0.0, 1.0)

  u_map = np.load(os.path.join(workdir, "test", "uncertainty.npy"))[0]
  top = results["top_k"][0]["name"]
  stem = f"01_{top}"
  panels = [
      (views.images[0], "capture: a test photo"),
      (draw("uncertainty_ply/model_colours.ply"), "model_colours.ply"),
      (draw("uncertainty_ply/coloured_by_uncertainty.ply"), "coloured_by_uncertainty.ply"),
      (u_map, "U per pixel (Eq. 10)"),
      (iio.imread(os.path.join(workdir, "next_views", "images", f"{stem}.png")),
       "next view #1: mean render"),
      (iio.imread(os.path.join(workdir, "next_views", "uncertainty", f"{stem}.png")),
       "next view #1: U map"),
  ]
  fig, axes = plt.subplots(1, len(panels), figsize=(2.0 * len(panels), 2.35), layout="constrained")
  for ax, (image, title) in zip(axes, panels, strict=True):
    ax.imshow(image, cmap="magma" if np.ndim(image) == 2 else None)
    ax.set_title(title, fontsize=7)
    ax.set_xticks([])
    ax.set_yticks([])
  fig.savefig(out, dpi=110)
  plt.close(fig)
  print(f"figure written to {out}")


def main(argv):
  del argv
  from mfsample.your_data import run_next_views

  root = os.path.abspath(_WORKDIR.value)
  write_capture(os.path.join(root, "capture"))
  results = run_next_views(loop_config(os.path.join(root, "capture")), os.path.join(root, "job"))
  print(f"test PSNR {results['test']['psnr']:.2f} dB, next views "
        f"{[t['name'] for t in results['top_k']]}")
  figure(os.path.join(root, "job"), _OUT.value)


if __name__ == "__main__":
  app.run(main)
