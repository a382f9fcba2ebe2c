"""The figure of an uncertainty job: where the next views are, and what U sees there.

Left: the cameras seen along the capture's "up" axis (the plane of the two directions in
which the camera centres spread most): training views as black dots, candidates coloured by
U, the top k numbered in red. Right, one column per proposed view: its image when the
candidate has one, the mean model's render, and the per-pixel U map (Eq. 10); below, the same
for the first test views. All U maps of the figure share one colour scale.
"""

import numpy as np


def _plt():
  import matplotlib
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt
  return plt


def _plane(points, reference):
  """2D coordinates of `points` [N, 3] on the two main axes of `reference` [M, 3]."""
  ref = np.asarray(reference, np.float64)
  center = ref.mean(axis=0)
  _, _, vt = np.linalg.svd(ref - center, full_matrices=False)
  return (np.asarray(points, np.float64) - center) @ vt[:2].T


def next_views_figure(path, *, train_centers, candidate_centers, u, top, top_renders, top_maps,
                      top_images=None, test_renders=(), test_maps=(), title=""):
  """Writes the figure to `path` (PNG).

  Args:
    train_centers: [T, 3] training camera centres.
    candidate_centers: [B, 3] candidate camera centres.
    u: [B] U of every candidate.
    top: [k] indices of the proposed candidates, best first.
    top_renders, top_maps: [k, H, W, 3] mean renders and [k, H, W] U maps of them.
    top_images: optional [k, H, W, 3] captured images of them.
    test_renders, test_maps: the same for a few test views.
    title: figure title.
  """
  plt = _plt()
  k = len(top)
  cols = max(k, len(test_renders), 1)
  rows = (3 if top_images is not None else 2) + (2 if len(test_renders) else 0)
  fig = plt.figure(figsize=(3.4 + 1.6 * cols, 1.6 * rows + 0.6))
  grid = fig.add_gridspec(rows, cols + 2, width_ratios=[1.0, 1.0] + [0.75] * cols)
  ax = fig.add_subplot(grid[:, :2])
  all_centers = np.concatenate([train_centers, candidate_centers])
  t2, c2 = _plane(train_centers, all_centers), _plane(candidate_centers, all_centers)
  sc = ax.scatter(c2[:, 0], c2[:, 1], c=u, cmap="viridis", s=18, zorder=2)
  bar = fig.colorbar(sc, ax=ax, orientation="horizontal", fraction=0.05, pad=0.03,
                     label="U of the candidate")
  bar.ax.tick_params(labelsize=7)
  bar.ax.xaxis.get_major_locator().set_params(nbins=4)
  ax.scatter(t2[:, 0], t2[:, 1], color="black", s=14, zorder=3, label="training views")
  for rank, i in enumerate(top):
    ax.scatter(c2[i, 0], c2[i, 1], s=110, facecolor="white", edgecolor="tab:red", lw=1.5,
               zorder=4)
    ax.annotate(str(rank + 1), c2[i], ha="center", va="center", fontsize=7, color="tab:red",
                zorder=5)
  ax.set_aspect("equal")
  ax.set_xticks([])
  ax.set_yticks([])
  ax.legend(loc="lower left", fontsize=7, frameon=False)
  ax.set_title("cameras (red: next views by U)", fontsize=9)

  maps = [np.asarray(m) for m in list(top_maps) + list(test_maps)]
  vmax = max((float(m.max()) for m in maps), default=1.0) or 1.0

  def show(r, c, image, label=None, is_map=False):
    a = fig.add_subplot(grid[r, c + 2])
    if is_map:
      a.imshow(np.asarray(image), cmap="magma", vmin=0.0, vmax=vmax)
    else:
      a.imshow(np.clip(np.asarray(image), 0.0, 1.0))
    a.set_xticks([])
    a.set_yticks([])
    if label:
      a.set_title(label, fontsize=8)
    return a

  for j in range(k):
    r = 0
    if top_images is not None:
      show(r, j, top_images[j], f"#{j + 1}: image")
      r += 1
    show(r, j, top_renders[j], f"#{j + 1}: render" if top_images is None else
         ("mean render" if j == 0 else None))
    show(r + 1, j, top_maps[j], f"U = {float(np.asarray(top_maps[j]).sum()):.3g}", True)
  base = 3 if top_images is not None else 2
  for j in range(len(test_renders)):
    show(base, j, test_renders[j], "test view" if j == 0 else None)
    show(base + 1, j, test_maps[j], None, True)
  if title:
    fig.suptitle(title, fontsize=10)
  fig.tight_layout()
  fig.savefig(path, dpi=120)
  plt.close(fig)
  return path
