"""The training experiment: `train_and_evaluate(config, workdir)` and its `JOB`.

Trains a stochastic field on the dataset of `config.data` (resuming from the workdir's
checkpoints), evaluates its mean on the test views (PSNR, SSIM, LPIPS, uncertainty maps) and
writes the metrics, images and the model as a 3DGS `.ply`.
"""

import json
import os
import time

from mfsample import config_blocks, jobs
from mfsample.data import datasets as data_lib
from mfsample.samplers import sample_z
from mfsample.train.config import recipe, train_spec, validate
from mfsample.train.loop import run_training


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
    wd.stage(f"loading the data ({config.data.kind})")
    dataset = data_lib.load_dataset(config_blocks.data_spec(config.data))
    # Made before training: a network that cannot be loaded stops the run before it trains.
    lpips_fn = metrics.make_lpips(config.eval.lpips_net) if config.eval.lpips_net else None
    wd.write_config()
    settings, _ = train_spec(config)
    extent = settings.extent
    if extent is None:  # 3DGS's, from the training cameras
      extent = data_lib.scene_extent(dataset.train.cameras)
    plan = recipe(config, extent=extent)
    model = plan.initial_model(seed=int(config.seed), bounds=dataset.bounds,
                               points=dataset.points)
    result = run_training(model, dataset.train, settings, seed=int(config.seed), extent=extent,
                          checkpoint_dir=wd.file("checkpoints"),
                          checkpoint_every=config.train.checkpoint_every,
                          keep_checkpoints=config.train.keep_checkpoints,
                          progress=config.train.progress, record={"job": JOB.name})
    state, setup = result.state, result.setup
    wd.write_json("train_log.json", result.history, indent=2)

    model = state.model
    z = None
    if model.spec.stochastic and config.eval.uncertainty_samples > 0:
      # Scrambled Sobol with the training's seed + 1 (not the training's own points).
      z = sample_z(model, int(config.eval.uncertainty_samples),
                   seed=int(config.sampler.z_seed) + 1)
    t0 = time.perf_counter()
    wd.stage(f"evaluating the {len(dataset.test)} test views")
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
        "sampler_spec": model.spec.to_dict(),
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


# Fields a resumed run may change: the speed-only ones, the progress bar, and which
# checkpoints are written and kept (a restored state is bit-identical whichever it is).
FREE_FIELDS = config_blocks.speed_only_fields() + ("train.progress", "train.checkpoint_every",
                                                   "train.keep_checkpoints")
JOB = jobs.Job("training", "training", train_and_evaluate, validate, FREE_FIELDS,
               ("checkpoints", "metrics.json", "train_log.json"), report=report,
               progress_field="train.progress")
