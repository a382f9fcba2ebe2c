"""The AUSE benchmark's figure: per scene, one test view, each model's error and maps.

Rows: the ground truth (image, exact depth), then one row per model: its mean render, its
depth error (grey where it does not count) and its maps (Ours: colour U and depth variance;
the deterministic model: its baselines', FisherRF, ActiveNeRF, post-hoc B_hat). A map is
shown by its rank among the counted pixels (0 = least, 1 = most uncertain), since AUSE sees
only the order; the panel title gives its AUSE on this view. The PNG is stored with a
256-colour palette (Pillow, which matplotlib depends on): a third of the size, for the docs.
"""

import io
import os

import numpy as np

from mfsample._json import atomic_path
from mfsample.quality.tables import BASELINE_LABELS, MAP_LABELS, model_label


def _plt():
  import matplotlib
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt
  return plt


def _ranks(values, mask):
  """Values -> their rank in [0, 1] among the masked pixels (nan elsewhere)."""
  out = np.full(values.shape, np.nan)
  v = values[mask]
  if v.size:
    order = np.argsort(np.argsort(v, kind="stable"), kind="stable")
    out[mask] = order / max(v.size - 1, 1)
  return out


def scene_figure(scene, test_views, records, arrays, path, view=0, seed=None):
  """Writes the figure of `scene` (test view `view`, the first seed's models) to `path`.

  Args:
    scene: scene name.
    test_views: `Views` of the test cameras (images, depths).
    records: the benchmark's records (the models of this scene are used).
    arrays: {(scene, seed, model): the unit's arrays (render, depth_error, mask, maps)}.
    path: PNG to write.
    view: index among the test views.
    seed: which seed's models (default: the first found).
  """
  plt = _plt()
  mine = [r for r in records if r["scene"] == scene]
  if seed is None and mine:
    seed = mine[0]["seed"]
  mine = [r for r in mine if r["seed"] == seed]
  if not mine:
    return None
  rows = len(mine) + 1
  cols = 2 + max(len(r["methods"]) for r in mine)  # image, error, then every map
  fig, axes = plt.subplots(rows, cols, figsize=(1.4 * cols, 1.45 * rows), squeeze=False)
  for ax in axes.ravel():
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
      spine.set_visible(False)
  cmap = plt.get_cmap("viridis").with_extremes(bad="0.75")  # grey: pixels not counted
  err_cmap = plt.get_cmap("magma").with_extremes(bad="0.75")
  true_depth = np.where(test_views.alphas[view] > 0, test_views.depths[view], np.nan)
  axes[0, 0].imshow(test_views.images[view], interpolation="nearest")
  axes[0, 0].set_title("test view", fontsize=7)
  axes[0, 1].imshow(true_depth, cmap="magma", interpolation="nearest")
  axes[0, 1].set_title("exact depth", fontsize=7)
  err_max = 0.0
  loaded = []
  for r in mine:
    unit = arrays[(scene, seed, r["model"])]
    loaded.append(unit)
    err_max = max(err_max, float(np.max(unit["depth_error"][view][unit["mask"][view]],
                                        initial=0.0)))
  for row, (r, unit) in enumerate(zip(mine, loaded, strict=True), start=1):
    mask = unit["mask"][view]
    axes[row, 0].imshow(unit["render"][view], interpolation="nearest")
    axes[row, 0].set_ylabel(model_label(r["model"]), fontsize=7)
    axes[row, 1].imshow(np.where(mask, unit["depth_error"][view], np.nan), cmap=err_cmap,
                        vmin=0.0, vmax=err_max or 1.0, interpolation="nearest")
    axes[row, 1].set_title(f"depth error (MAE {r['views'][view]['depth_mae'] or 0:.3f})",
                           fontsize=7)
    for col, method in enumerate(r["methods"], start=2):
      ause = r["views"][view]["ause"].get(method, {}).get("mae")
      label = BASELINE_LABELS.get(method) or MAP_LABELS.get(method, method)
      axes[row, col].imshow(_ranks(unit[f"map_{method}"][view], mask), cmap=cmap,
                            vmin=0.0, vmax=1.0, interpolation="nearest")
      axes[row, col].set_title(f"{label}, AUSE {ause:.2f}" if ause is not None else label,
                               fontsize=7)
  fig.suptitle(f"{scene}: test view {view}; maps as ranks (grey: not counted)", fontsize=8)
  fig.tight_layout()
  os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
  buffer = io.BytesIO()
  fig.savefig(buffer, format="png", dpi=80)
  plt.close(fig)
  from PIL import Image

  buffer.seek(0)
  with atomic_path(path) as tmp:
    Image.open(buffer).convert("RGB").quantize(256, method=Image.Quantize.FASTOCTREE).save(
        tmp, optimize=True)
  return path
