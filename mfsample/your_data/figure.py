"""The figure of an uncertainty job: where the next views are, and what U sees there.

Left: the cameras seen along the capture's "up" axis (the plane of the two directions in
which the camera centres spread most): training views as black dots, candidates coloured by
U, the top k numbered in red. Right, one column per proposed view: its image when the
candidate has one, the mean model's render, and the per-pixel U map (Eq. 10) with its U;
below, the same for the first test views. All U maps of the figure share one colour scale.

The layout holds from one candidate to hundreds: the camera panel keeps a square box around
whatever the centres span (a single pair of cameras is a line, not a collapsed axis), the
image grid is sized by its own rows and columns, and the rank numbers are placed where they
overlap neither each other nor the markers' neighbours' numbers.
"""

import numpy as np

# Inches: the camera panel's side, one image cell's side.
_PANEL = 3.6
_CELL = 1.45
_NAME_CHARS = 16  # longer view names are shortened in titles


def _plt():
  import matplotlib
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt
  return plt


def _plane(points, reference):
  """2D coordinates of `points` [N, 3] on the two main axes of `reference` [M, 3]."""
  ref = np.asarray(reference, np.float64).reshape(-1, 3)
  center = ref.mean(axis=0)
  _, _, vt = np.linalg.svd(ref - center, full_matrices=True)
  return (np.asarray(points, np.float64).reshape(-1, 3) - center) @ vt[:2].T


def _short(name):
  name = str(name)
  return name if len(name) <= _NAME_CHARS else name[:_NAME_CHARS - 1] + "\u2026"


def _square_limits(ax, xy):
  """Equal, square limits around the points `xy` [N, 2] with a margin (any spread, even 0)."""
  lo, hi = xy.min(axis=0), xy.max(axis=0)
  span = float(np.max(hi - lo))
  span = span if span > 1e-12 else max(float(np.max(np.abs(xy))), 1.0)
  mid = 0.5 * (lo + hi)
  half = 0.62 * span
  ax.set_xlim(mid[0] - half, mid[0] + half)
  ax.set_ylim(mid[1] - half, mid[1] + half)
  ax.set_aspect("equal", adjustable="box")


def _label_ranks(ax, fig, positions):
  """Numbers 1..k next to the markers at `positions` [k, 2], placed greedily (best rank first)
  at the first of several offsets where the text overlaps no number placed before."""
  renderer = fig.canvas.get_renderer()
  placed = []
  for rank, xy in enumerate(positions, start=1):
    for radius in (9, 15, 22, 30):
      for angle in np.deg2rad([45, 135, -45, -135, 90, -90, 0, 180]):
        offset = (radius * np.cos(angle), radius * np.sin(angle))
        text = ax.annotate(str(rank), xy, xytext=offset, textcoords="offset points",
                           ha="center", va="center", fontsize=7, color="tab:red",
                           fontweight="bold", zorder=6, annotation_clip=False)
        text.set_in_layout(False)
        box = text.get_window_extent(renderer).expanded(1.15, 1.15)
        if not any(box.overlaps(other) for other in placed):
          placed.append(box)
          break
        text.remove()
      else:
        continue
      break
    else:  # crowded beyond every offset: keep the last place rather than drop the number
      text = ax.annotate(str(rank), xy, xytext=(0, 34), textcoords="offset points",
                         ha="center", va="center", fontsize=7, color="tab:red", zorder=6,
                         annotation_clip=False)
      text.set_in_layout(False)
      placed.append(text.get_window_extent(renderer))


def _camera_panel(fig, ax, train_centers, candidate_centers, u, top):
  train = np.asarray(train_centers, np.float64).reshape(-1, 3)
  cand = np.asarray(candidate_centers, np.float64).reshape(-1, 3)
  both = np.concatenate([train, cand])
  t2, c2 = _plane(train, both), _plane(cand, both)
  size = float(np.clip(60.0 / np.sqrt(max(len(cand), 1)), 6.0, 40.0))
  sc = ax.scatter(c2[:, 0], c2[:, 1], c=np.asarray(u, np.float64), cmap="viridis", s=size,
                  zorder=2)
  bar = fig.colorbar(sc, ax=ax, orientation="horizontal", fraction=0.05, pad=0.04,
                     shrink=0.85)
  bar.set_label("U of the candidate", fontsize=8)
  bar.ax.tick_params(labelsize=7)
  bar.ax.xaxis.get_major_locator().set_params(nbins=3)
  ax.scatter(t2[:, 0], t2[:, 1], color="black", s=16, zorder=3, label="training views")
  ax.scatter(c2[top, 0], c2[top, 1], s=70, facecolor="none", edgecolor="tab:red", lw=1.5,
             zorder=4, label="next views")
  _square_limits(ax, np.concatenate([t2, c2]))
  ax.set_xticks([])
  ax.set_yticks([])
  ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.01), ncol=2, fontsize=7,
            frameon=False, handletextpad=0.2, columnspacing=1.0)
  ax.set_title(f"{len(cand)} candidate{'s' if len(cand) != 1 else ''} by U", fontsize=9)
  return c2[np.asarray(top, int)]


def next_views_figure(path, **kwargs):
  """Writes the figure (`build_figure(**kwargs)`) to `path` (PNG, atomically)."""
  from mfsample._json import atomic_path

  plt = _plt()
  fig = build_figure(**kwargs)
  with atomic_path(path) as tmp:
    fig.savefig(tmp, dpi=120)
  plt.close(fig)
  return path


def build_figure(*, train_centers, candidate_centers, u, top, top_renders, top_maps,
                 top_images=None, test_renders=(), test_maps=(), title="", top_names=None,
                 test_names=None):
  """The figure as a matplotlib `Figure` (drawn once: its layout is final).

  Args:
    train_centers: [T, 3] training camera centres.
    candidate_centers: [B, 3] candidate camera centres (B >= 1).
    u: [B] U of every candidate.
    top: [k] indices of the proposed candidates, best first.
    top_renders, top_maps: [k, H, W, 3] mean renders and [k, H, W] U maps of them.
    top_images: optional [k, H, W, 3] captured images of them.
    test_renders, test_maps: the same for a few test views.
    title: figure title.
    top_names, test_names: optional names of the proposed and test views (column titles).
  """
  plt = _plt()
  k, n_test = len(top), len(test_renders)
  cols = max(k, n_test, 1)
  top_rows = 3 if top_images is not None else 2
  rows = top_rows + (2 if n_test else 0)
  h, w = np.shape(top_renders)[1:3]
  cell_h = _CELL * h / w + 0.28  # the image and its title or U line
  grid_w, grid_h = cols * _CELL + 1.0, rows * cell_h + 0.3
  panel_h = _PANEL + 1.3  # the panel, its legend and its colour bar
  height = max(panel_h, grid_h) + (0.4 if title else 0.1)
  fig = plt.figure(figsize=(_PANEL + 0.4 + grid_w, height), layout="constrained")
  left, right = fig.subfigures(1, 2, width_ratios=[_PANEL + 0.4, grid_w], wspace=0.02)
  # The panel keeps its size at the top when the image grid is the taller part.
  spare = max(grid_h - panel_h, 0.0)
  camera_ax = left.add_subplot(left.add_gridspec(2, 1, height_ratios=[panel_h, spare + 1e-3])[0])
  top_xy = _camera_panel(fig, camera_ax, train_centers, candidate_centers, u, top)

  maps = [np.asarray(m) for m in list(top_maps) + list(test_maps)]
  vmax = max((float(m.max()) for m in maps), default=1.0) or 1.0
  axes = right.subplots(rows, cols, squeeze=False)
  for a in axes.ravel():
    a.set_xticks([])
    a.set_yticks([])
    a.set_frame_on(False)
  shown = None

  def show(r, c, image, is_map=False):
    nonlocal shown
    a = axes[r, c]
    a.set_frame_on(True)
    if is_map:
      shown = a.imshow(np.asarray(image), cmap="magma", vmin=0.0, vmax=vmax)
      a.set_xlabel(f"U = {float(np.asarray(image).sum()):.3g}", fontsize=7, labelpad=2)
    else:
      a.imshow(np.clip(np.asarray(image), 0.0, 1.0))
    return a

  def block(first_row, renders, images, pixel_maps, names, heading):
    for j in range(len(renders)):
      r = first_row
      if images is not None:
        show(r, j, images[j])
        r += 1
      show(r, j, renders[j])
      show(r + 1, j, pixel_maps[j], is_map=True)
      name = f" {_short(names[j])}" if names is not None else ""
      axes[first_row, j].set_title(f"{heading(j)}{name}", fontsize=7, pad=3)
    labels = (["image"] if images is not None else []) + ["mean render", "U per pixel"]
    for i, label in enumerate(labels):
      axes[first_row + i, 0].set_ylabel(label, fontsize=7)

  block(0, top_renders, top_images, top_maps, top_names, lambda j: f"next #{j + 1}")
  if n_test:
    block(top_rows, test_renders, None, test_maps, test_names, lambda j: "test")
  if shown is not None:
    bar = right.colorbar(shown, ax=axes, shrink=0.6, fraction=0.04, pad=0.02)
    bar.ax.tick_params(labelsize=7)
    bar.set_label("per-pixel variance", fontsize=7)
  if title:
    fig.suptitle(title, fontsize=9)
  fig.set_dpi(120)  # the resolution it is saved at: texts measured here are the ones written
  fig.canvas.draw()  # the layout first: the rank numbers are placed in final screen space
  _label_ranks(camera_ax, fig, top_xy)
  return fig
