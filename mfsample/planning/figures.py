"""Figures of a planning run: the chosen cameras per strategy, and the uncertainty landscape.

* `camera_figure`: one panel per strategy, the camera sphere seen from above (+z): a camera
  at azimuth a and polar angle p sits at (sin p cos a, sin p sin a); rings mark polar
  angles of 30, 60 and 90 degrees. Grey dots are the candidate pool, the red star the
  initial view, numbered circles the views in the order chosen (hollow: a new pose found by
  optimisation, then captured).
* `landscape_figure`: U (Eq. 10) of the 1-view model over a latitude-longitude grid of
  cameras (azimuth across, polar angle down), the training view as a red dot, and an
  optimisation from a random start (yellow) to its end (green), as in the paper's Fig. 7.
"""

import math

import numpy as np

from mfsample._json import atomic_path

_ORDER_CMAP = "viridis"


def _plt():
  import matplotlib
  matplotlib.use("Agg")
  import matplotlib.pyplot as plt
  return plt


def _top_view(uv):
  uv = np.asarray(uv, np.float64).reshape(-1, 2)
  az, polar = 2.0 * math.pi * uv[:, 0], math.pi * uv[:, 1]
  return np.sin(polar) * np.cos(az), np.sin(polar) * np.sin(az)


def camera_figure(records, pool, path, seed=0):
  """Writes the chosen cameras of every strategy (runs of `seed`) to `path` (PNG)."""
  from mfsample.planning.poses import camera_to_uv

  plt = _plt()
  runs = [r for r in records if int(r["seed"]) == int(seed)]
  if not runs:
    return None
  cols = min(4, len(runs))
  rows = math.ceil(len(runs) / cols)
  fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.4 * rows), squeeze=False)
  cand_x, cand_y = _top_view(camera_to_uv(pool.candidates.cameras, pool.sphere.center))
  cmap = plt.get_cmap(_ORDER_CMAP)
  theta = np.linspace(0.0, 2.0 * math.pi, 200)
  for ax in axes.ravel()[len(runs):]:
    ax.axis("off")
  for ax, run in zip(axes.ravel(), runs, strict=False):
    for deg in (30, 60, 90):
      r = math.sin(math.radians(deg))
      ax.plot(r * np.cos(theta), r * np.sin(theta), color="0.85", lw=0.6, zorder=0)
    ax.scatter(cand_x, cand_y, s=6, color="0.7", zorder=1)
    x, y = _top_view(run["uv"])
    n = len(x)
    ax.plot(x, y, color="0.6", lw=0.5, zorder=2)
    for i in range(n):
      color = cmap(i / max(n - 1, 1))
      if i == 0:
        ax.scatter(x[i], y[i], marker="*", s=140, color="tab:red", zorder=4)
        continue
      new = run["indices"][i] is None
      ax.scatter(x[i], y[i], s=90, facecolor="white" if new else color, edgecolor=color,
                 lw=1.5, zorder=3)
      ax.annotate(str(i + 1), (x[i], y[i]), ha="center", va="center", fontsize=6, zorder=5,
                  color="black" if new else "white")
    m = run["metrics"].get(str(n)) or {}
    psnr = f", {m['psnr']:.2f} dB" if m.get("psnr") is not None else ""
    ax.set_title(f"{run['label']}{psnr}", fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlim(-1.08, 1.08)
    ax.set_ylim(-1.08, 1.08)
    ax.set_xticks([])
    ax.set_yticks([])
  # Two lines: with two strategies the figure is 6.4 inches wide and one line was clipped.
  fig.suptitle(f"{pool.name}: chosen cameras seen from above, seed {seed}\n"
               "star: initial view; numbers: order; hollow: optimised pose", fontsize=9)
  fig.tight_layout()
  with atomic_path(path) as tmp:
    fig.savefig(tmp, dpi=130)
  plt.close(fig)
  return path


def landscape_figure(land, path, title="U of the 1-view model (Eq. 10)"):
  """Writes the uncertainty landscape `land` (from `runner.landscape`) to `path` (PNG)."""
  plt = _plt()
  values, u, v = land["values"], land["u"], land["v"]
  fig, ax = plt.subplots(figsize=(8.0, 3.2))
  az = 360.0 * np.asarray(u)
  polar = 180.0 * np.asarray(v)
  du = az[1] - az[0] if len(az) > 1 else 360.0
  dv = polar[1] - polar[0] if len(polar) > 1 else 1.0
  im = ax.imshow(values, origin="upper", aspect="auto", cmap="magma",
                 extent=(az[0] - du / 2, az[-1] + du / 2, polar[-1] + dv / 2, polar[0] - dv / 2))
  fig.colorbar(im, ax=ax, label="U")
  if "candidates_uv" in land:
    c = np.asarray(land["candidates_uv"])
    ax.scatter(360.0 * c[:, 0], 180.0 * c[:, 1], s=4, color="0.8", label="candidates")
  t = np.asarray(land["train_uv"])
  ax.scatter(360.0 * t[:, 0], 180.0 * t[:, 1], s=60, color="red", edgecolor="white",
             label="training view", zorder=4)
  if "trajectory" in land:
    traj = np.asarray(land["trajectory"])
    ax.plot(360.0 * traj[:, 0], 180.0 * traj[:, 1], color="white", lw=1.0, zorder=3)
    ax.scatter(360.0 * traj[0, 0], 180.0 * traj[0, 1], s=50, color="gold", edgecolor="k",
               label="random start", zorder=5)
    ax.scatter(360.0 * traj[-1, 0], 180.0 * traj[-1, 1], s=50, color="limegreen",
               edgecolor="k", label="optimised", zorder=5)
  ax.set_xlim(0.0, 360.0)
  ax.set_xlabel("azimuth (degrees)")
  ax.set_ylabel("polar angle (degrees)")
  ax.set_title(title, fontsize=10)
  ax.legend(loc="lower right", fontsize=7, framealpha=0.7)
  fig.tight_layout()
  with atomic_path(path) as tmp:
    fig.savefig(tmp, dpi=130)
  plt.close(fig)
  return path
