"""The training experiment: `train_and_evaluate(config, workdir)` and its `JOB`.

Trains a stochastic field on the dataset of `config.data` (resuming from the workdir's
checkpoints), evaluates its mean on the test views (PSNR, SSIM, LPIPS, uncertainty maps) and
writes the metrics, images and the model as a 3DGS `.ply`.
"""

import json
import os
import time

import jax

from mfsample import jobs
from mfsample.data import datasets as data_lib
from mfsample.samplers import sobol_z
from mfsample.train.config import validate
from mfsample.train.loop import RESUME_FREE_FIELDS, train


def train_and_evaluate(config, workdir):
  """Loads the data, trains (resuming from `workdir`), evaluates, writes everything.

  Writes to `workdir`: `checkpoints/`, `config.json`, `train_log.json`, `metrics.json`
  (test PSNR / SSIM / LPIPS of the mean model, iterations, wall-clock), `images/`
  (renders, ground truth, uncertainty maps of test views) and `point_cloud.ply`, each
  atomically. Nothing is written before the config is validated
  (`mfsample.train.config.validate`), the workdir is known to hold no results of another
  config (`JOB`) and the data are loaded.

  Returns:
    the final `TrainState`.
  """
  from mfsample import metrics
  from mfsample.data import ply as export_ply
  from mfsample.train import evaluate as eval_lib

  with jobs.open_workdir(JOB, config, workdir) as wd:
    dataset = data_lib.load_dataset(config.data)
    wd.write_config()
    result = train(config, dataset.train, bounds=dataset.bounds,
                   checkpoint_dir=wd.file("checkpoints"), points=dataset.points)
    state, setup = result.state, result.setup
    wd.write_json("train_log.json", result.history, indent=2)

    lpips_fn = metrics.make_lpips(config.eval.lpips_net) if config.eval.lpips_net else None
    model = state.model
    z = None
    if model.spec.stochastic and config.eval.uncertainty_samples > 0:
      from mfsample import samplers
      m = int(config.eval.uncertainty_samples)
      key = jax.random.PRNGKey(setup.seed + 3)
      rows = sobol_z(m, model.spec.rank, int(config.sampler.z_seed) + 1) \
          if model.spec.kind == "lowrank" else None
      z = samplers.draw_z(model, m, key, rows)
    t0 = time.perf_counter()
    ev = eval_lib.evaluate(model, dataset.test, background=dataset.background,
                           settings=setup.step_config.settings, lpips_fn=lpips_fn,
                           uncertainty_z=z)
    eval_seconds = time.perf_counter() - t0
    if wd.writes:
      eval_lib.save_images(wd.file("images"), ev, dataset.test, num=config.eval.save_images)
    if config.eval.export_ply and wd.writes:
      export_ply.export_ply(wd.file("point_cloud.ply"), model)  # atomic
    summary = dict(ev.metrics)
    summary.update({
        "sampler": model.spec.kind, "rank": model.spec.rank,
        "steps": int(state.step), "live_gaussians": model.num_live,
        "train_seconds": result.train_seconds, "eval_seconds": eval_seconds,
        "resolution": [int(dataset.train.images.shape[2]),
                       int(dataset.train.images.shape[1])],
        "num_train_views": len(dataset.train), "per_view": ev.per_view,
    })
    wd.write_json("metrics.json", summary, indent=2)
    return state


def report(state, workdir):
  """What `experiments/train.py` prints: the test metrics of the trained model."""
  with open(os.path.join(workdir, "metrics.json"), encoding="utf-8") as f:
    m = json.load(f)
  lpips = f", LPIPS {m['lpips']:.3f}" if m.get("lpips") is not None else ""
  return (f"{m['sampler']} field, {m['steps']} steps, {m['live_gaussians']} Gaussians: test "
          f"PSNR {m['psnr']:.2f} dB, SSIM {m['ssim']:.3f}{lpips} ({m['num_views']} views); "
          f"written to {workdir}")


JOB = jobs.Job("training", train_and_evaluate, validate, RESUME_FREE_FIELDS,
               ("checkpoints", "metrics.json", "train_log.json"), report=report,
               progress_field="train.progress")
