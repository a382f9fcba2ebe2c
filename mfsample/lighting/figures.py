"""Figures of a light-planning run: metrics against lights, relit test views, U over lights.

* `metrics.png`: PSNR, SSIM and LPIPS of the relit test views against the number of lights,
  one line per strategy.
* `relit.png`: one test camera under a few test lights: the ground truth beside each
  strategy's model after the last light (clamped linear radiance).
* `u_sphere.png`: U over the light sphere for the model of the first phase (uniform light
  only): U of the light from each direction (the SH projection of a point light, at the
  common norm) on a latitude-longitude map, and U of the n one-hot lights beside Q's
  eigenvalues (times norm^2: the U of its eigenvectors), whose largest is the maximum of U.
"""

import os

import numpy as np

from mfsample.lighting import lights as lights_lib
from mfsample.lighting import strategies
from mfsample.lighting import uncertainty as lu
from mfsample.lighting.tables import METRICS


def _plt():
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  return plt


def _order(names):
  return [n for n in strategies.NAMES if n in names] + [n for n in names
                                                        if n not in strategies.NAMES]


def metrics_figure(summary, total, path):
  """`metrics.png` (see the module docstring) from `tables.summarise`'s dict."""
  plt = _plt()
  shown = [m for m in METRICS if any(s["by_lights"].get("1", {}).get(m[0]) is not None
                                     for s in summary.values())]
  fig, axes = plt.subplots(1, len(shown), figsize=(4.2 * len(shown), 3.2), squeeze=False)
  counts = np.arange(1, total + 1)
  for ax, (metric, label, arrow, _) in zip(axes[0], shown, strict=True):
    for name in _order(summary):
      s = summary[name]
      values = [s["by_lights"].get(str(n), {}).get(metric) for n in counts]
      ax.plot(counts, [np.nan if v is None else v for v in values], marker="o", ms=3,
              label=s["label"])
    ax.set_xlabel("number of lights")
    ax.set_title(f"{label} {arrow}")
    ax.set_xticks(counts)
    ax.grid(alpha=0.3)
  axes[0][0].legend(fontsize=7)
  fig.tight_layout()
  fig.savefig(path, dpi=110)
  plt.close(fig)


def relit_figure(truth, predictions, rows, path, row_labels=None):
  """`relit.png`: one row per test light, ground truth then each strategy.

  Args:
    truth: [R, H, W, 3] ground-truth images (linear).
    predictions: {label: [R, H, W, 3]} predictions (linear).
    rows: R row indices (for the labels).
    path: output file.
    row_labels: optional R strings.
  """
  plt = _plt()
  cols = ["ground truth"] + list(predictions)
  fig, axes = plt.subplots(len(rows), len(cols), figsize=(1.6 * len(cols), 1.7 * len(rows)),
                           squeeze=False)
  for r in range(len(rows)):
    images = [truth[r]] + [p[r] for p in predictions.values()]
    for c, image in enumerate(images):
      ax = axes[r][c]
      ax.imshow(np.clip(np.asarray(image, np.float32), 0.0, 1.0), interpolation="nearest")
      ax.set_xticks([])
      ax.set_yticks([])
      if r == 0:
        ax.set_title(cols[c], fontsize=7)
    if row_labels is not None:
      axes[r][0].set_ylabel(row_labels[r], fontsize=7)
  fig.tight_layout()
  fig.savefig(path, dpi=110)
  plt.close(fig)


def u_over_directions(q, norm, height, width):
  """(U [h, w] of the point light from each grid direction at `norm`, dirs [h, w, 3])."""
  dirs, _ = lights_lib.direction_grid(height, width)
  y = lights_lib.basis_values(dirs, np.asarray(q).shape[0])
  y = y * (norm / np.linalg.norm(y, axis=-1, keepdims=True))
  return lu.quadratic_u(q, y), dirs


def u_sphere_figure(q, norm, path, height=32, width=64):
  """`u_sphere.png` (see the module docstring) for the quadratic form `q` [n, n]."""
  plt = _plt()
  q = np.asarray(q, np.float64)
  n = q.shape[0]
  values, _ = u_over_directions(q, norm, height, width)
  one_hot = norm ** 2 * np.diag(q)
  eig = norm ** 2 * np.sort(np.linalg.eigvalsh(q))[::-1]
  fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 3.2),
                                 gridspec_kw={"width_ratios": [1.4, 1.0]})
  im = ax0.imshow(values, extent=(0, 360, 180, 0), aspect="auto", cmap="magma")
  ax0.set_xlabel("azimuth of the light (deg, from +x towards +y)")
  ax0.set_ylabel("polar angle (deg, from +z)")
  ax0.set_title("U of a point light from each direction", fontsize=9)
  fig.colorbar(im, ax=ax0, fraction=0.04)
  idx = np.arange(n)
  ax1.bar(idx - 0.2, one_hot, width=0.4, label="one-hot light e_j")
  ax1.bar(idx + 0.2, eig, width=0.4, label="eigenvector j of Q (sorted)")
  ax1.set_xticks(idx)
  ax1.set_xlabel("coefficient / eigenvector index j")
  ax1.set_title("U at the common norm", fontsize=9)
  ax1.legend(fontsize=7)
  fig.tight_layout()
  fig.savefig(path, dpi=110)
  plt.close(fig)


def write_figures(config, workdir, results, ctx, predictions):
  """The three figures of a finished run (called by `protocol.run_light_planning`).

  Args:
    predictions: {strategy name: [K, T, H, W, 3] its final model's test renders}.
  """
  from mfsample.lighting.tables import summarise

  summary = summarise(results["shared"], results["runs"])
  metrics_figure(summary, int(config.num_lights), os.path.join(workdir, "metrics.png"))
  kinds = list(ctx.test_kinds)
  rows = ([i for i, k in enumerate(kinds) if k == "environment"][:2]
          + [i for i, k in enumerate(kinds) if k == "random"][:1])
  camera = 0
  shown = {}
  for name in _order([r["strategy"] for r in results["runs"]]):
    if name in predictions:
      shown[strategies.STRATEGIES[name].label] = predictions[name][rows, camera]
  truth = ctx.test_truth[rows, camera]
  relit_figure(truth, shown, rows, os.path.join(workdir, "relit.png"),
               row_labels=[f"{kinds[i]} {i}" for i in rows])
  u_sphere_figure(np.asarray(results["shared"]["q"]), ctx.norm,
                  os.path.join(workdir, "u_sphere.png"), int(config.figures.sphere_height),
                  int(config.figures.sphere_width))
