"""Speed against accuracy for the knobs a user turns, measured on trained lego models.

Every curve pairs a time with an accuracy, in one process on one machine:

* samples M of U (Eq. 10): time per candidate vs the relative error of U and the rank
  correlation of the candidates' U with a many-sample reference (scrambled Sobol z,
  several scramblings);
* scoring resolution (`strategy.score_downscale`): time per candidate vs the rank
  correlation of the candidates' U with U at full resolution (same z);
* SH degree: forward render time vs test PSNR of a trained degree-3 model cut to its first
  (d + 1)^2 coefficients (truncation, not retraining: an upper bound on the loss);
* Gaussian budget: forward render time vs test PSNR when only the K most opaque Gaussians
  are kept (pruning, not retraining).
Both render compact arrays (live Gaussians only, only the SH bands kept), so the time
is what a model of that size costs;
* rank k and the sampler kind: read from `results/train_step.json` (ms per step, peak
  memory) when `benchmarks/train_step.py` has been run.

The trained models are the lego runs of `benchmarks/train_quality.py` (`--size=100`):

  PYTHONPATH=. python benchmarks/tradeoffs.py \
      --stochastic=workdirs/quality100/rank2_every_step \
      --deterministic=workdirs/quality100/deterministic
"""

import json
import os
import platform
import statistics
import time

from absl import app, flags

_STOCHASTIC = flags.DEFINE_string(
    "stochastic", "workdirs/quality100/rank2_every_step",
    "Workdir of a rank-2 lego run that sampled at every step (its B_hat is trained).")
_DETERMINISTIC = flags.DEFINE_string("deterministic", "workdirs/quality100/deterministic",
                                     "Workdir of a trained deterministic lego run.")
_DATA = flags.DEFINE_string("data", "../shared/data/lego", "NeRF Synthetic lego folder.")
_CANDIDATES = flags.DEFINE_integer("candidates", 12, "Candidate cameras (train views).")
_SAMPLES = flags.DEFINE_list("samples", ["2", "4", "8", "16"], "M values to measure.")
_REFERENCE_M = flags.DEFINE_integer("reference_samples", 32, "M of the reference U.")
_SCRAMBLES = flags.DEFINE_integer("scrambles", 3, "Sobol scrambling seeds per M.")
_DOWNSCALES = flags.DEFINE_list("downscales", ["1", "2", "4"], "Scoring downscales.")
_TEST_VIEWS = flags.DEFINE_integer("test_views", 25, "Test views for the PSNR curves.")
_KEEP = flags.DEFINE_list("keep", ["1.0", "0.5", "0.25", "0.125"],
                          "Fractions of the Gaussians kept (most opaque first).")
_OUT = flags.DEFINE_string("out", "results/tradeoffs.json", "JSON output.")
_PLOT = flags.DEFINE_string("plot", "results/tradeoffs.png", "Figure ('' to skip).")


def _load_run(workdir):
  """(config, dataset, model, settings) of the newest checkpoint of a training workdir."""
  import ml_collections

  from mfsample.train import data as data_lib
  from mfsample.train import loop

  with open(os.path.join(workdir, "config.json")) as f:
    config = ml_collections.ConfigDict(json.load(f))
  config.data.path = _DATA.value
  dataset = data_lib.load_dataset(config.data)
  setup = loop.make_setup(config, dataset.train)
  restored = loop.restore_latest(config, setup, dataset.bounds,
                                 os.path.join(workdir, "checkpoints"))
  if restored is None:
    raise FileNotFoundError(f"no checkpoint in {workdir}/checkpoints")
  state, setup, _ = restored
  return config, dataset, state.model, setup.step_config.settings


def _timed(fn, repeats=3):
  """(result, median seconds) of `fn()` after one untimed call (compilation)."""
  import jax

  out = jax.block_until_ready(fn())
  times = []
  for _ in range(repeats):
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    times.append(time.perf_counter() - t0)
  return out, statistics.median(times)


def _spearman(a, b):
  import scipy.stats

  return float(scipy.stats.spearmanr(a, b).statistic)


def _scores(model, cameras, z, settings, background):
  """U of every camera (sequential, budget grown until nothing overflows)."""
  import numpy as np

  from mfsample import uncertainty as unc
  from mfsample.renderer.budget import render_with_budget

  values = []
  for i in range(len(cameras)):
    u, settings = render_with_budget(unc.uncertainty, settings, model, cameras[i], z,
                                     background=background)
    values.append(float(u.value))
  return np.asarray(values), settings


def _time_one_candidate(model, camera, z, settings, background):
  from mfsample import uncertainty as unc

  return _timed(lambda: unc.uncertainty(model, camera, z, settings=settings,
                                        background=background).value)[1]


def samples_and_resolution(workdir):
  import jax.numpy as jnp
  import numpy as np

  from mfsample import uncertainty as unc
  from mfsample.planning.poses import downscale_camera

  _, dataset, model, settings = _load_run(workdir)
  bg = jnp.asarray(dataset.background, jnp.float32)
  train = dataset.train
  idx = np.linspace(0, len(train) - 1, _CANDIDATES.value).round().astype(int)
  cams = train.cameras[idx]
  ref_z = unc.uncertainty_z(model, _REFERENCE_M.value, seed=10_000)
  ref, settings = _scores(model, cams, ref_z, settings, bg)
  out = {"run": workdir, "live_gaussians": model.num_live, "resolution": cams.width,
         "candidates": len(idx), "reference_samples": _REFERENCE_M.value, "samples": [],
         "downscales": []}
  for m in map(int, _SAMPLES.value):
    errors, rhos = [], []
    for seed in range(_SCRAMBLES.value):
      z = unc.uncertainty_z(model, m, seed=seed)
      values, settings = _scores(model, cams, z, settings, bg)
      errors.extend(np.abs(values - ref) / ref)
      rhos.append(_spearman(values, ref))
    z = unc.uncertainty_z(model, m, seed=0)
    seconds = _time_one_candidate(model, cams[0], z, settings, bg)
    row = {"M": m, "ms_per_candidate": 1e3 * seconds,
           "median_relative_error": float(np.median(errors)),
           "spearman_vs_reference": float(np.mean(rhos))}
    out["samples"].append(row)
    print(f"[samples] M={m:3d}: {row['ms_per_candidate']:7.1f} ms/candidate, "
          f"U error {row['median_relative_error']:.3f}, rank corr "
          f"{row['spearman_vs_reference']:.3f}", flush=True)

  z = unc.uncertainty_z(model, 2, seed=0)
  full, settings = _scores(model, cams, z, settings, bg)
  for d in map(int, _DOWNSCALES.value):
    small = downscale_camera(cams, d)
    values, _ = _scores(model, small, z, settings, bg)
    seconds = _time_one_candidate(model, small[0], z, settings, bg)
    row = {"downscale": d, "resolution": small.width, "ms_per_candidate": 1e3 * seconds,
           "spearman_vs_full": _spearman(values, full)}
    out["downscales"].append(row)
    print(f"[resolution] {small.width:4d}^2: {row['ms_per_candidate']:7.1f} ms/candidate, "
          f"rank corr with {cams.width}^2 {row['spearman_vs_full']:.3f}", flush=True)
  return out


def _downscaled(cameras, d):
  from mfsample.planning.poses import downscale_cameras

  return downscale_cameras(cameras, d)


def _psnr_and_time(gaussians, views, settings, background):
  """Mean test PSNR of `gaussians` and the median forward render time of one view (ms)."""
  import jax
  import jax.numpy as jnp
  import numpy as np

  from mfsample import metrics
  from mfsample.renderer import render
  from mfsample.renderer.budget import render_with_budget

  psnrs = []
  for i in range(len(views)):
    out, settings = render_with_budget(render, settings, gaussians, views.cameras[i],
                                       background=background)
    psnrs.append(float(metrics.psnr(jnp.clip(out.rgb, 0, 1), jnp.asarray(views.images[i]))))
  # Time with the smallest budget that fits (the forward cost grows with the budget).
  settings = render_with_budget(render, settings.replace(max_intersections=1024), gaussians,
                                views.cameras[0], background=background)[1]
  fn = jax.jit(lambda g, c: render(g, c, background=background, settings=settings).rgb)
  seconds = _timed(lambda: fn(gaussians, views.cameras[0]), repeats=15)[1]
  return float(np.mean(psnrs)), 1e3 * seconds


def _rows(gaussians, index):
  """The Gaussians at `index` as a compact array (no masked padding left to project)."""
  import jax

  from mfsample._pytree import replace

  return jax.tree.map(lambda x: x[index], replace(gaussians, mask=None))


def sh_and_budget(workdir):
  """Test PSNR and forward time of compact models: fewer SH bands, fewer Gaussians."""
  import jax.numpy as jnp
  import numpy as np

  from mfsample._pytree import replace
  from mfsample.model import mean_gaussians

  _, dataset, model, settings = _load_run(workdir)
  bg = jnp.asarray(dataset.background, jnp.float32)
  test = dataset.test
  idx = np.linspace(0, len(test) - 1, min(_TEST_VIEWS.value, len(test))).round().astype(int)
  test = test.subset(list(idx))
  live = np.flatnonzero(np.asarray(model.mask))
  full = _rows(mean_gaussians(model), live)  # the live Gaussians only, degree 3
  out = {"run": workdir, "live_gaussians": len(live), "test_views": len(test),
         "resolution": test.cameras.width, "sh_degree": [], "keep": []}
  for degree in range(model.max_sh_degree, -1, -1):
    g = replace(full, sh=full.sh[:, :(degree + 1) ** 2])  # the bands a degree-d model holds
    psnr, ms = _psnr_and_time(g, test, settings, bg)
    out["sh_degree"].append({"degree": degree, "psnr": psnr, "forward_ms": ms})
    print(f"[sh] degree {degree}: PSNR {psnr:.2f} dB, forward {ms:.1f} ms", flush=True)
  opacity = np.asarray(model.params.mean["opacity_logits"]).reshape(-1)[live]
  order = np.argsort(-opacity)  # most opaque first
  for frac in map(float, _KEEP.value):
    k = max(int(round(frac * len(live))), 1)
    psnr, ms = _psnr_and_time(_rows(full, np.sort(order[:k])), test, settings, bg)
    out["keep"].append({"fraction": frac, "gaussians": k, "psnr": psnr, "forward_ms": ms})
    print(f"[budget] {k:6d} Gaussians: PSNR {psnr:.2f} dB, forward {ms:.1f} ms", flush=True)
  return out


def rank_from_train_step(path="results/train_step.json"):
  if not os.path.exists(path):
    return None
  with open(path) as f:
    return json.load(f)


def _curve(ax, rows, x, y, label, **axis):
  """One panel: `y` against `x` over `rows`, each point annotated with `label(row)`."""
  ax.plot([r[x] for r in rows], [r[y] for r in rows], "o-")
  for r in rows:
    ax.annotate(label(r), (r[x], r[y]))
  ax.set(**axis)


def _plot(results, path):
  import matplotlib

  matplotlib.use("Agg")
  import matplotlib.pyplot as plt

  fig, axes = plt.subplots(1, 4, figsize=(17, 3.8))
  unc, rend = results["uncertainty"], results["rendering"]
  _curve(axes[0], unc["samples"], "ms_per_candidate", "median_relative_error",
         lambda r: f"M={r['M']}", xlabel="ms per candidate",
         ylabel="median relative error of U",
         title=f"samples M (ref. M={unc['reference_samples']})")
  _curve(axes[1], unc["downscales"], "ms_per_candidate", "spearman_vs_full",
         lambda r: f"{r['resolution']}²", xlabel="ms per candidate",
         ylabel="rank correlation with full res.", title="scoring resolution")
  _curve(axes[2], rend["sh_degree"], "forward_ms", "psnr", lambda r: str(r["degree"]),
         xlabel="forward render ms", ylabel="test PSNR (dB)", title="SH degree (truncated)")
  _curve(axes[3], rend["keep"], "forward_ms", "psnr", lambda r: str(r["gaussians"]),
         xlabel="forward render ms", ylabel="test PSNR (dB)",
         title="Gaussian budget (pruned)")
  fig.tight_layout()
  fig.savefig(path, dpi=110)
  print(f"saved {path}")


def main(argv):
  del argv
  import jax

  started = time.time()
  results = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                         "backend": jax.default_backend()},
             "uncertainty": samples_and_resolution(_STOCHASTIC.value),
             "rendering": sh_and_budget(_DETERMINISTIC.value),
             "rank": rank_from_train_step(),
             }
  results["seconds"] = time.time() - started
  from mfsample._json import write_json
  write_json(_OUT.value, results)
  print(f"saved {_OUT.value}")
  if _PLOT.value:
    _plot(results, _PLOT.value)


if __name__ == "__main__":
  app.run(main)
