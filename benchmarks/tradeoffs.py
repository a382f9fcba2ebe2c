"""Speed against accuracy for the knobs a user turns, measured on trained lego models.

Every curve pairs a time with an accuracy, both measured in this process:

* samples M of U (Eq. 10): time per candidate vs the relative error of U and the rank
  correlation of the candidates' U with a many-sample reference (scrambled Sobol z,
  several scramblings);
* scoring resolution (`strategy.score_downscale`): time per candidate vs the rank
  correlation of the candidates' U with U at full resolution (same z);
* SH degree: forward render time vs test PSNR of a trained model cut to its first
  (d + 1)^2 coefficients (truncation, not retraining: an upper bound on the loss);
* Gaussian budget: forward render time vs test PSNR when only the K most opaque Gaussians
  are kept (pruning, not retraining).
Both rendering curves render compact arrays (live Gaussians only, only the SH bands kept),
so the time is what a model of that size costs. Times are medians of repeated calls after
a compiling call. Rank k and the sampler kind are read from `benchmarks/train_step.py`'s
JSON (ms per step, peak memory) and copied into this one.

The trained models come from `benchmarks/train_quality.py`:

  python benchmarks/train_quality.py --size=100 --steps=5000 \
      --variants=deterministic,rank2_every_step --workdir=workdirs/benchmarks/quality100
  python benchmarks/train_step.py --rounds=3
  python benchmarks/tradeoffs.py \
      --stochastic=workdirs/benchmarks/quality100/rank2_every_step \
      --deterministic=workdirs/benchmarks/quality100/deterministic
"""

import functools
import json
import os
import statistics
import time

from absl import app, flags

_STOCHASTIC = flags.DEFINE_string(
    "stochastic", "workdirs/benchmarks/train_quality/rank2_every_step",
    "Workdir of a rank-2 lego run that sampled at every step (its B_hat is trained): "
    "benchmarks/train_quality.py's rank2_every_step.")
_DETERMINISTIC = flags.DEFINE_string(
    "deterministic", "workdirs/benchmarks/train_quality/deterministic",
    "Workdir of a trained deterministic lego run: benchmarks/train_quality.py's deterministic.")
_TRAIN_STEP = flags.DEFINE_string(
    "train_step", "workdirs/benchmarks/train_step.json",
    "JSON of benchmarks/train_step.py (rank and sampler kind); '' to leave them out.")
_DATA = flags.DEFINE_string("data", "data/nerf_synthetic/lego",
                            "NeRF Synthetic lego folder (the runs' test views).")
_CANDIDATES = flags.DEFINE_integer("candidates", 12, "Candidate cameras (train views).")
_SAMPLES = flags.DEFINE_list("samples", ["2", "4", "8", "16"], "M values to measure.")
_REFERENCE_M = flags.DEFINE_integer("reference_samples", 32, "M of the reference U.")
_SCRAMBLES = flags.DEFINE_integer("scrambles", 3, "Sobol scrambling seeds per M.")
_DOWNSCALES = flags.DEFINE_list("downscales", ["1", "2", "4"], "Scoring downscales.")
_TEST_VIEWS = flags.DEFINE_integer("test_views", 25, "Test views for the PSNR curves.")
_KEEP = flags.DEFINE_list("keep", ["1.0", "0.5", "0.25", "0.125"],
                          "Fractions of the Gaussians kept (most opaque first).")
_OUT = flags.DEFINE_string("out", "workdirs/benchmarks/tradeoffs.json", "JSON output.")
_PLOT = flags.DEFINE_string("plot", "workdirs/benchmarks/tradeoffs.png", "Figure ('' to skip).")


def check_run(workdir, flag):
  """Raises FileNotFoundError naming `flag` unless `workdir` holds a finished training run."""
  from mfsample.train import checkpoint as ckpt

  config = os.path.join(workdir, "config.json")
  if not os.path.isfile(config) or not ckpt.list_checkpoints(os.path.join(workdir,
                                                                           "checkpoints")):
    raise FileNotFoundError(
        f"{flag}={workdir!r} holds no trained run (missing {config} or checkpoints/). "
        "Train one with benchmarks/train_quality.py (see this script's docstring) or point "
        f"{flag} at a workdir of experiments/train.py.")


def load_run(workdir, data=None):
  """(dataset, model, render settings) of the newest checkpoint of a training workdir.

  `data` replaces the run's `config.data.path` when the run trained on NeRF Synthetic.
  """
  import ml_collections

  from mfsample._bench import require_scene_folder
  from mfsample.config_blocks import data_spec
  from mfsample.config_record import WRITTEN_BY
  from mfsample.data import datasets as data_lib
  from mfsample.train import loop
  from mfsample.train.config import recipe

  with open(os.path.join(workdir, "config.json")) as f:
    record = json.load(f)
  config = ml_collections.ConfigDict({k: v for k, v in record.items() if k != WRITTEN_BY})
  if config.data.kind == "blender" and data is not None:
    require_scene_folder(data, "--data")
    config.data.path = data
  dataset = data_lib.load_dataset(data_spec(config.data))
  # The run's start and setup, as the training job built them: the template of its state.
  seed, extent = int(config.seed), config.data.extent
  if extent is None:
    extent = data_lib.scene_extent(dataset.train.cameras)
  plan = recipe(config, extent=extent)
  model = plan.initial_model(seed=seed, bounds=dataset.bounds, points=dataset.points)
  setup = loop.make_setup(plan.settings, model, seed=seed, extent=extent,
                          num_views=len(dataset.train))
  restored = loop.restore_latest(os.path.join(workdir, "checkpoints"), setup,
                                 lambda: loop.init_state(model, setup))
  if restored is None:
    raise FileNotFoundError(f"no checkpoint in {workdir}/checkpoints")
  state, setup, _ = restored
  return dataset, state.model, setup.step_config.settings


def read_train_step(path, flag="--train_step"):
  """{path, machine, table} of `benchmarks/train_step.py`'s JSON at `path`."""
  if not os.path.isfile(path):
    raise FileNotFoundError(f"{flag}={path!r} does not exist: run "
                            f"benchmarks/train_step.py --out={path} first, or pass {flag}= "
                            "to leave rank and sampler out.")
  with open(path) as f:
    record = json.load(f)
  return {"path": path, "machine": record.get("machine"), "table": record["table"]}


def timed(fn, repeats=3):
  """(result, median seconds) of `fn()` over `repeats` calls after one untimed call."""
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

  from mfsample import view_uncertainty as unc
  from mfsample.renderer.budget import render_with_budget

  values = []
  for i in range(len(cameras)):
    u, settings = render_with_budget(unc.uncertainty, settings, model, cameras[i], z,
                                     background=background)
    values.append(float(u.value))
  return np.asarray(values), settings


def _ms_one_candidate(model, camera, z, settings, background, repeats):
  from mfsample import view_uncertainty as unc

  return 1e3 * timed(lambda: unc.uncertainty(model, camera, z, settings=settings,
                                             background=background).value, repeats)[1]


def samples_and_resolution(model, dataset, settings, *, candidates, samples, reference_samples,
                           scrambles, downscales, repeats=3):
  """U's accuracy and cost against M and against the scoring resolution.

  Args:
    model: a trained stochastic `Model`.
    dataset: its `Dataset`; `candidates` of its training cameras, evenly spaced, are scored.
    settings: starting `RenderSettings` (grown on overflow).
    candidates: number of candidate cameras.
    samples: the M to measure.
    reference_samples: M of the reference U (Sobol seed 10000).
    scrambles: Sobol scramblings (seeds 0..scrambles-1) per M.
    downscales: scoring downscale factors (1 = full resolution), M = 2, Sobol seed 0.
    repeats: timed calls per time (median).

  Returns:
    {live_gaussians, resolution, candidates, reference_samples,
     samples: [{M, ms_per_candidate, median_relative_error (|U - U_ref| / U_ref over
       candidates and scramblings), spearman_vs_reference (mean over scramblings)}],
     downscales: [{downscale, resolution, ms_per_candidate, spearman_vs_full}]}.
  """
  import jax.numpy as jnp
  import numpy as np

  from mfsample.planning.poses import downscale_camera
  from mfsample.samplers import sample_z

  bg = jnp.asarray(dataset.background, jnp.float32)
  train = dataset.train
  idx = np.linspace(0, len(train) - 1, candidates).round().astype(int)
  cams = train.cameras[idx]
  ref_z = sample_z(model, reference_samples, seed=10_000)
  ref, settings = _scores(model, cams, ref_z, settings, bg)
  out = {"live_gaussians": model.num_live, "resolution": cams.width, "candidates": len(idx),
         "reference_samples": reference_samples, "samples": [], "downscales": []}
  for m in map(int, samples):
    errors, rhos = [], []
    for seed in range(scrambles):
      z = sample_z(model, m, seed=seed)
      values, settings = _scores(model, cams, z, settings, bg)
      errors.extend(np.abs(values - ref) / ref)
      rhos.append(_spearman(values, ref))
    z = sample_z(model, m, seed=0)
    row = {"M": m, "ms_per_candidate": _ms_one_candidate(model, cams[0], z, settings, bg,
                                                         repeats),
           "median_relative_error": float(np.median(errors)),
           "spearman_vs_reference": float(np.mean(rhos))}
    out["samples"].append(row)
    print(f"[samples] M={m:3d}: {row['ms_per_candidate']:7.1f} ms/candidate, "
          f"U error {row['median_relative_error']:.3f}, rank corr "
          f"{row['spearman_vs_reference']:.3f}", flush=True)

  z = sample_z(model, 2, seed=0)
  full, settings = _scores(model, cams, z, settings, bg)
  for d in map(int, downscales):
    small = downscale_camera(cams, d)
    values, _ = _scores(model, small, z, settings, bg)
    row = {"downscale": d, "resolution": small.width,
           "ms_per_candidate": _ms_one_candidate(model, small[0], z, settings, bg, repeats),
           "spearman_vs_full": _spearman(values, full)}
    out["downscales"].append(row)
    print(f"[resolution] {small.width:4d}^2: {row['ms_per_candidate']:7.1f} ms/candidate, "
          f"rank corr with {cams.width}^2 {row['spearman_vs_full']:.3f}", flush=True)
  return out


@functools.cache
def _forward_rgb():
  """The jitted forward render, image only (what a viewer computes), settings static."""
  import jax

  from mfsample.renderer import render

  return jax.jit(lambda g, camera, background, settings: render(
      g, camera, background=background, settings=settings).rgb, static_argnames=("settings",))


def _psnr_and_ms(gaussians, views, settings, background, repeats):
  """Mean PSNR of `gaussians` over `views` and the median forward render time of one (ms)."""
  import jax.numpy as jnp
  import numpy as np

  from mfsample import metrics
  from mfsample.renderer import render
  from mfsample.renderer.budget import render_with_budget

  # Timed with the smallest budget that fits the first view (the forward cost grows with
  # the budget); the other views grow it where they need more.
  timing = render_with_budget(render, settings.replace(max_intersections=1024), gaussians,
                              views.cameras[0], background=background)[1]
  fn, camera = _forward_rgb(), views.cameras[0]
  seconds = timed(lambda: fn(gaussians, camera, background, settings=timing), repeats)[1]
  psnrs, settings = [], timing
  for i in range(len(views)):
    out, settings = render_with_budget(render, settings, gaussians, views.cameras[i],
                                       background=background)
    psnrs.append(float(metrics.psnr(jnp.clip(out.rgb, 0, 1), jnp.asarray(views.images[i]))))
  return float(np.mean(psnrs)), 1e3 * seconds


def _rows(gaussians, index):
  """The Gaussians at `index` as a compact array (no masked padding left to project)."""
  import jax

  from mfsample._pytree import replace

  return jax.tree.map(lambda x: x[index], replace(gaussians, mask=None))


def sh_and_budget(model, dataset, settings, *, test_views, keep, repeats=15):
  """Test PSNR and forward time of compact models: fewer SH bands, fewer Gaussians.

  Args:
    model: a trained `Model` (its mean is rendered).
    dataset: its `Dataset`; `test_views` evenly spaced test views are rendered.
    settings: the run's `RenderSettings` (the budget is refitted from 1024 intersections
      per model, and grown on overflow).
    test_views: number of test views for the PSNR.
    keep: fractions of the live Gaussians kept, the most opaque first.
    repeats: timed calls per time (median).

  Returns:
    {live_gaussians, test_views, resolution,
     sh_degree: [{degree, psnr, forward_ms}] from the model's degree down to 0,
     keep: [{fraction, gaussians, psnr, forward_ms}]}.
  """
  import jax.numpy as jnp
  import numpy as np

  from mfsample._pytree import replace
  from mfsample.model import mean_gaussians

  bg = jnp.asarray(dataset.background, jnp.float32)
  test = dataset.test
  idx = np.linspace(0, len(test) - 1, min(test_views, len(test))).round().astype(int)
  test = test.subset(list(idx))
  live = np.flatnonzero(np.asarray(model.mask))
  full = _rows(mean_gaussians(model), live)  # the live Gaussians only, every SH band
  out = {"live_gaussians": len(live), "test_views": len(test),
         "resolution": test.cameras.width, "sh_degree": [], "keep": []}
  for degree in range(model.max_sh_degree, -1, -1):
    g = replace(full, sh=full.sh[:, :(degree + 1) ** 2])  # the bands a degree-d model holds
    psnr, ms = _psnr_and_ms(g, test, settings, bg, repeats)
    out["sh_degree"].append({"degree": degree, "psnr": psnr, "forward_ms": ms})
    print(f"[sh] degree {degree}: PSNR {psnr:.2f} dB, forward {ms:.1f} ms", flush=True)
  opacity = np.asarray(model.params.mean["opacity_logits"]).reshape(-1)[live]
  order = np.argsort(-opacity)  # most opaque first
  for frac in map(float, keep):
    k = max(int(round(frac * len(live))), 1)
    psnr, ms = _psnr_and_ms(_rows(full, np.sort(order[:k])), test, settings, bg, repeats)
    out["keep"].append({"fraction": frac, "gaussians": k, "psnr": psnr, "forward_ms": ms})
    print(f"[budget] {k:6d} Gaussians: PSNR {psnr:.2f} dB, forward {ms:.1f} ms", flush=True)
  return out


def _curve(ax, rows, x, y, label, **axis):
  """One panel: `y` against `x` over `rows`, each point annotated with `label(row)`."""
  ax.plot([r[x] for r in rows], [r[y] for r in rows], "o-")
  for r in rows:
    ax.annotate(label(r), (r[x], r[y]))
  ax.set(**axis)


def plot(results, path):
  """The four curves of `results` (this script's JSON) side by side, saved to `path`."""
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
  os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
  fig.savefig(path, dpi=110)
  plt.close(fig)


def main(argv):
  del argv
  from mfsample._bench import machine
  from mfsample._json import write_json

  # Every input is checked before the long measurements start.
  try:
    check_run(_STOCHASTIC.value, "--stochastic")
    check_run(_DETERMINISTIC.value, "--deterministic")
    rank = read_train_step(_TRAIN_STEP.value) if _TRAIN_STEP.value else None
  except FileNotFoundError as error:
    raise app.UsageError(str(error)) from error
  started = time.time()
  dataset, model, settings = load_run(_STOCHASTIC.value, _DATA.value)
  uncertainty = samples_and_resolution(
      model, dataset, settings, candidates=_CANDIDATES.value, samples=_SAMPLES.value,
      reference_samples=_REFERENCE_M.value, scrambles=_SCRAMBLES.value,
      downscales=_DOWNSCALES.value)
  dataset, model, settings = load_run(_DETERMINISTIC.value, _DATA.value)
  rendering = sh_and_budget(model, dataset, settings, test_views=_TEST_VIEWS.value,
                            keep=_KEEP.value)
  results = {"machine": machine(),
             "uncertainty": {"run": _STOCHASTIC.value, **uncertainty},
             "rendering": {"run": _DETERMINISTIC.value, **rendering},
             "rank": rank, "seconds": time.time() - started}
  write_json(_OUT.value, results)
  print(f"saved {_OUT.value}")
  if _PLOT.value:
    plot(results, _PLOT.value)
    print(f"saved {_PLOT.value}")


if __name__ == "__main__":
  app.run(main)
