"""Uncertainty maps and next views for a dataset, or for a 3DGS model trained elsewhere.

`run_uncertainty(config, workdir)`:

1. loads the dataset of `config.data` (NeRF Synthetic, LLFF, a COLMAP capture, a built-in
   scene or random Gaussians) and splits its training views: every `views.train_every`-th
   trains, the others are the "unused" candidates;
2. trains a stochastic field on them (`mfsample.train.train`), or, with `posthoc.ply`, fits
   B_hat to that model's frozen Gaussians (`mfsample.train.posthoc.fit_spread`); both
   checkpoint into `workdir/checkpoints` and a killed call resumes from there;
3. renders every test view with its per-pixel U map (Eq. 10);
4. scores the candidates (the unused views, or poses on a sphere) by U and proposes the top
   k; with candidate images, Spearman's rho of U against the model's error there
   (`mfsample.planning.u_error`) says how far to trust the ranking on this capture;
5. writes the figure and the results.

The workdir: `config.json` (a later call with a different config is refused, naming the
fields), `checkpoints/`, `train_log.json`, `point_cloud.ply` (a trained field's mean),
`test/` (renders, U maps as PNG and `uncertainty.npy`, `metrics.json`), `next_views.json`,
`next_views.png` and `results.json`. A call on a finished workdir returns its results.
"""

import json
import os
import time

import jax.numpy as jnp
import numpy as np

from mfsample import config_checks as checks
from mfsample import uncertainty as unc
from mfsample import workdir as workdir_lib
from mfsample._json import write_json
from mfsample.train.initial import INIT_FROM

# Fields that change only how a call looks or how fast it goes: a later call may differ.
RESUME_FREE_FIELDS = ("train.progress", "render.chunks_per_step", "next_views.figure")


def check_config(config):
  """Validates the fields the job reads (before anything is written); ConfigError names
  the field."""
  from mfsample.train.config import validate
  validate(config)  # every training field (data, model, sampler, loss, train, render, eval)
  checks.check_choice(config, "sampler.kind", ("lowrank", "block", "diagonal"))
  checks.check_choice(config, "model.init_from", INIT_FROM)
  checks.check_choice(config, "next_views.candidates", ("unused", "sphere"))
  for field in ("views.train_every", "next_views.k", "next_views.score_downscale",
                "next_views.sphere_views", "posthoc.steps", "train.num_steps"):
    checks.check_int(config, field, minimum=1)
  checks.check_int(config, "next_views.samples", minimum=2)  # one sample: U = 0
  checks.check_int(config, "eval.save_images", minimum=0)
  if config.data.kind in ("colmap", "llff"):
    checks.check_int(config, "data.holdout_every", minimum=2)
  if (config.model.init_from == "points" and config.data.kind != "colmap"
      and not config.posthoc.ply):
    raise checks.ConfigError(f"config.model.init_from = 'points' needs the sparse points of a "
                             f"COLMAP capture, but config.data.kind = {config.data.kind!r}")
  if config.next_views.candidates == "unused" and config.views.train_every == 1:
    raise checks.ConfigError("config.views.train_every = 1 trains on every view and leaves no "
                             "unused candidate: set it > 1 or next_views.candidates = 'sphere'")
  if config.posthoc.ply:
    from mfsample.data import resolve_path
    if not resolve_path(config.posthoc.ply).is_file():
      raise FileNotFoundError(f"config.posthoc.ply = {config.posthoc.ply!r}: no such file "
                              f"({resolve_path(config.posthoc.ply)})")


def check_workdir(config, workdir):
  """Refuses a workdir holding work (checkpoints, results) of a different config, naming the
  differing fields. A workdir whose earlier call failed before computing anything (a wrong
  data path, say) is taken over."""
  workdir_lib.check_same_config(
      config, workdir, free_fields=RESUME_FREE_FIELDS,
      has_results=workdir_lib.holds_results(workdir, "results.json", "checkpoints"),
      results="a run")


def run_uncertainty(config, workdir):
  """Trains or fits, maps the test views' uncertainty and proposes the next views.

  Args:
    config: `mfsample.next_views.default_config()` or a variant (`configs/uncertainty.py`).
    workdir: output folder (see the module docstring); resumed when it exists.

  Returns:
    the results dict also written to `results.json`.
  """
  from mfsample.data import datasets as data_lib

  check_config(config)
  check_workdir(config, workdir)
  os.makedirs(workdir, exist_ok=True)
  results_path = os.path.join(workdir, "results.json")
  if os.path.exists(results_path):
    with open(results_path) as f:
      return json.load(f)
  workdir_lib.write_config(config, workdir)
  t0 = time.perf_counter()

  dataset = data_lib.load_dataset(config.data)
  every = int(config.views.train_every)
  index = np.arange(len(dataset.train))
  train_idx, unused_idx = index[index % every == 0], index[index % every != 0]
  train_views = dataset.train.subset(train_idx)
  result, kind = _train_or_fit(config, dataset, train_views, workdir)
  model, settings = result.state.model, result.setup.step_config.settings
  write_json(os.path.join(workdir, "train_log.json"), result.history)
  if kind == "joint" and config.eval.export_ply:
    from mfsample.data.ply import export_ply
    export_ply(os.path.join(workdir, "point_cloud.ply"), model)

  background = jnp.asarray(dataset.background, jnp.float32)
  # One z (M = next_views.samples) for the test maps and the candidates, and one budget
  # shared by every render: test views and candidates of one size share the compiled code.
  z = unc.uncertainty_z(model, int(config.next_views.samples), int(config.next_views.z_seed))
  state = {"settings": settings}
  test = _test_maps(config, model, dataset, z, state, os.path.join(workdir, "test"))
  center = 0.5 * (np.asarray(dataset.bounds[0], np.float64)
                  + np.asarray(dataset.bounds[1], np.float64))
  proposal = _propose(config, model, dataset, train_idx, unused_idx, center, z, state,
                      background)
  write_json(os.path.join(workdir, "next_views.json"), proposal["record"])
  if config.next_views.figure:
    from mfsample.next_views.figure import next_views_figure

    shown = min(4, len(dataset.test))
    next_views_figure(
        os.path.join(workdir, "next_views.png"),
        train_centers=np.asarray(train_views.cameras.center),
        candidate_centers=np.asarray(proposal["cameras"].center), u=proposal["u"],
        top=proposal["top"], top_renders=proposal["renders"], top_maps=proposal["maps"],
        top_images=proposal["images"], test_renders=test["renders"][:shown],
        test_maps=test["maps"][:shown],
        title=f"{_scene_name(config)}: {kind} uncertainty, {len(train_views)} training views, "
              f"next {len(proposal['top'])} of {len(proposal['u'])} candidates")

  record = proposal["record"]
  results = {
      "scene": _scene_name(config), "kind": kind, "steps": int(result.state.step),
      "train_seconds": result.train_seconds, "live_gaussians": model.num_live,
      "num_train_views": len(train_views), "num_test_views": len(dataset.test),
      "test": test["metrics"],
      "next_views": {key: record[key] for key in ("candidates", "num_candidates", "samples",
                                                   "score_downscale", "rho_u_error",
                                                   "rho_u_angle", "rho_error_angle")},
      "top_k": [{"rank": t["rank"], "name": t["name"], "u": t["u"]} for t in record["top_k"]],
      "seconds_this_call": time.perf_counter() - t0,
  }
  write_json(results_path, results)
  return results


def _scene_name(config):
  from mfsample.data import resolve_path
  kind = config.data.kind
  if kind in ("blender", "colmap", "llff"):
    return resolve_path(config.data.path).name
  return config.data.scene if kind == "scene" else "synthetic"


def _train_or_fit(config, dataset, train_views, workdir):
  """(`TrainResult`, "joint" | "posthoc") with checkpoints in `workdir/checkpoints`."""
  from mfsample.data import resolve_path
  from mfsample.train import train
  from mfsample.train.posthoc import fit_spread

  checkpoint_dir = os.path.join(workdir, "checkpoints")
  if config.posthoc.ply:
    cfg = config.copy_and_resolve_references()
    with cfg.unlocked():
      cfg.train.num_steps = int(config.posthoc.steps)
    return fit_spread(cfg, train_views, resolve_path(config.posthoc.ply),
                      checkpoint_dir=checkpoint_dir), "posthoc"
  return train(config, train_views, bounds=dataset.bounds, checkpoint_dir=checkpoint_dir,
               points=dataset.points), "joint"


def _test_maps(config, model, dataset, z, state, directory):
  """Renders, U maps and metrics of every test view, with a progress bar; written to
  `directory`. Returns {"metrics", "renders", "maps"}."""
  from tqdm.auto import tqdm

  from mfsample import metrics as metrics_lib
  from mfsample.train import evaluate as eval_lib

  lpips_fn = metrics_lib.make_lpips(config.eval.lpips_net) if config.eval.lpips_net else None
  per_view = []
  for i in tqdm(range(len(dataset.test)), desc="test views", disable=not config.train.progress,
                dynamic_ncols=True):
    ev = eval_lib.evaluate(model, dataset.test.subset([i]), background=dataset.background,
                           settings=state["settings"], lpips_fn=lpips_fn, uncertainty_z=z)
    per_view.append(ev)
  merged = eval_lib.EvalResult(
      metrics={}, per_view={key: [e.per_view[key][0] if e.per_view[key] else None
                                  for e in per_view] for key in ("psnr", "ssim", "lpips")},
      images=np.concatenate([e.images for e in per_view]),
      uncertainty=np.concatenate([e.uncertainty for e in per_view]))
  eval_lib.save_images(directory, merged, dataset.test, num=int(config.eval.save_images))
  u = merged.uncertainty.reshape(len(per_view), -1).sum(axis=1)
  metrics = {"psnr": float(np.mean(merged.per_view["psnr"])),
             "ssim": float(np.mean(merged.per_view["ssim"])),
             "lpips": (float(np.mean(merged.per_view["lpips"])) if lpips_fn else None),
             "mean_u": float(np.mean(u)), "samples": int(z.shape[0]),
             "per_view": {"name": list(dataset.test.names), "u": u.tolist(),
                          **merged.per_view}}
  write_json(os.path.join(directory, "metrics.json"), metrics)
  return {"metrics": {k: v for k, v in metrics.items() if k != "per_view"},
          "renders": merged.images, "maps": merged.uncertainty}


def _render(model, camera, background, state):
  """[H, W, 3] mean render of one camera; the budget that sufficed is kept in
  `state["settings"]`. The jitted function of the test evaluation, so candidates of the
  test views' size compile nothing new."""
  from mfsample.renderer.budget import render_with_budget
  from mfsample.train.evaluate import render_mean

  out, state["settings"] = render_with_budget(render_mean, state["settings"], model, camera,
                                              background)
  return np.asarray(jnp.clip(out.rgb, 0.0, 1.0))


def _u(model, camera, z, background, state):
  """`uncertainty.Uncertainty` of one camera (budget kept in `state["settings"]`)."""
  from mfsample.renderer.budget import render_with_budget

  u, state["settings"] = render_with_budget(unc.uncertainty, state["settings"], model, camera,
                                            z, background=background)
  return u


def _propose(config, model, dataset, train_idx, unused_idx, center, z, state, background):
  """U of every candidate (progress bar), the top k with their renders and U maps, and the
  record. With candidate images, the error of the mean render there and Spearman's rho of U
  against it: the measure of `mfsample.planning.u_error` (U at the scoring size, the squared
  error at full size, over the unused views; rho with the angle to the nearest training
  view beside it)."""
  from scipy.stats import spearmanr
  from tqdm.auto import tqdm

  from mfsample.next_views.candidates import sphere_candidates, top_k
  from mfsample.planning.poses import angle_to_nearest, downscale_camera

  nv = config.next_views
  down = int(nv.score_downscale)
  record = {"candidates": nv.candidates, "samples": int(z.shape[0]),
            "score_downscale": down, "rho_u_error": None, "rho_u_angle": None,
            "rho_error_angle": None}
  if nv.candidates == "unused":
    cameras = dataset.train.cameras[unused_idx]
    images = np.asarray(dataset.train.images)[unused_idx]
    names = [dataset.train.names[i] for i in unused_idx] if dataset.train.names else [
        f"train_{i}" for i in unused_idx]
  else:
    cameras = sphere_candidates(dataset.train.cameras[train_idx], center, int(nv.sphere_views))
    images = None
    names = [f"sphere_{i:03d}" for i in range(len(cameras))]
  num = len(cameras)
  u, error = np.zeros(num), np.zeros(num)
  kept = {}  # the current top k: index -> (render, U map) at full size
  for i in tqdm(range(num), desc="candidates", disable=not config.train.progress,
                dynamic_ncols=True):
    camera = cameras[i]
    res = _u(model, downscale_camera(camera, down), z, background, state)
    u[i] = float(res.value)
    render = _render(model, camera, background, state) if images is not None or down == 1 \
        else None
    if images is not None:
      error[i] = float(np.mean((render - images[i]) ** 2))
    if down == 1:  # keep the renders and maps of the current top k only (memory)
      kept[i] = (render, np.asarray(res.pixel_map))
      kept = {j: kept[j] for j in top_k(u[:i + 1], int(nv.k)) if j in kept}
  top = top_k(u, int(nv.k))
  for i in top:
    if i not in kept:  # scored at a smaller size: render and map the proposals at full size
      camera = cameras[int(i)]
      kept[i] = (_render(model, camera, background, state),
                 np.asarray(_u(model, camera, z, background, state).pixel_map))
  if images is not None:
    rho = lambda a, b: float(spearmanr(a, b).correlation)
    both = dataset.train.cameras[np.concatenate([train_idx, unused_idx])]
    angle = angle_to_nearest(both, list(range(len(train_idx))), center)[len(train_idx):]
    record.update(rho_u_error=rho(u, error), rho_u_angle=rho(u, angle),
                  rho_error_angle=rho(error, angle))
  w2c = np.asarray(cameras.world_to_camera, np.float64)
  record.update(num_candidates=num, u=u.tolist(), names=names, top_k=[{
      "rank": rank + 1, "index": int(i), "name": names[i], "u": float(u[i]),
      "error": None if images is None else float(error[i]),
      "world_to_camera": w2c[i].tolist(),
      "intrinsics": {"fx": float(cameras.fx[i]), "fy": float(cameras.fy[i]),
                     "cx": float(cameras.cx[i]), "cy": float(cameras.cy[i]),
                     "width": int(cameras.width), "height": int(cameras.height)},
  } for rank, i in enumerate(top)])
  return {"record": record, "u": u, "top": top, "cameras": cameras,
          "images": None if images is None else images[top],
          "renders": np.stack([kept[i][0] for i in top]),
          "maps": np.stack([kept[i][1] for i in top])}
