"""Uncertainty maps and next views for a dataset, or for a 3DGS model trained elsewhere.

`run_next_views(config, workdir)`:

1. loads the dataset of `config.data` (NeRF Synthetic, LLFF, a COLMAP capture, a built-in
   scene or random Gaussians) and splits its training views: every `views.train_every`-th
   trains, the others are the "unused" candidates;
2. trains a stochastic field on them (`mfsample.train.run_training`), or, with `posthoc.ply`, fits
   B_hat to that model's frozen Gaussians (`mfsample.train.posthoc.fit_b_hat`); both
   checkpoint into `workdir/checkpoints` and a killed call resumes from there;
3. renders every test view with its per-pixel U map (Eq. 10); a post-hoc model whose mean
   renders them below `posthoc.min_psnr` does not reproduce the capture: a warning, and
   `warnings` in the results, say so;
4. scores the candidates (the unused views, or poses on a sphere) by U and proposes the top
   k; with candidate images, Spearman's rho of U against the model's error there
   (`mfsample.planning.u_error`) says how far to trust the ranking on this capture;
5. writes the figure and the results.

The workdir: `config.json` (a later call with a different config is refused, naming the
fields), `inputs.json` (the files read: a later call whose files changed stops, or computes
again as `data.inputs_changed` says), `checkpoints/`, `train_log.json`, `point_cloud.ply`
(a trained field's mean), `test/` (renders, U maps as PNG and `uncertainty.npy`,
`metrics.json`), `next_views.json`,
`next_views/` (the proposals as nerfstudio `transforms.json` and `camera_path.json`, the 3DGS
`cameras.json` SuperSplat imports, a COLMAP text model, and a mean render and U map each:
`mfsample.your_data.export`), `uncertainty_ply/` (the model with its uncertainty per
Gaussian over the candidates: `mfsample.your_data.uncertainty_ply`), `next_views.png` and
`results.json`. A call on a finished workdir returns its results, while the files they
point to are what it wrote (otherwise they are computed again, from the checkpoints).
"""

import os
import time
import warnings

import jax.numpy as jnp
import numpy as np

from mfsample import interrupts, jobs
from mfsample.config_blocks import data_spec, speed_only_fields
from mfsample.data import datasets, resolve_path
from mfsample.jobs import Budgets
from mfsample.samplers import sample_z
from mfsample.your_data.config import check_views, validate


def run_next_views(config, workdir):
  """Trains or fits, maps the test views' uncertainty and proposes the next views.

  Args:
    config: `mfsample.your_data.default_config()` or a variant (`configs/next_views.py`).
    workdir: output folder (see the module docstring); resumed when it exists.

  Returns:
    the results dict also written to `results.json`.
  """
  with jobs.open_workdir(JOB, config, workdir) as wd:
    finished = wd.read_json("results.json")
    if finished is not None:
      return finished
    t0 = time.perf_counter()
    wd.stage(f"loading the data ({config.data.kind})")
    spec = data_spec(config.data)
    dataset = datasets.load_dataset(spec)
    # What depends on the data alone is checked before anything is written or trained.
    check_views(config, len(dataset.train), dataset.train.cameras.width,
                dataset.train.cameras.height, spec.path)
    every = int(config.views.train_every)
    index = np.arange(len(dataset.train))
    train_idx, unused_idx = index[index % every == 0], index[index % every != 0]
    train_views = dataset.train.subset(train_idx)
    center = 0.5 * (np.asarray(dataset.bounds[0], np.float64)
                    + np.asarray(dataset.bounds[1], np.float64))
    candidates = _candidates(config, dataset, train_idx, unused_idx, center)
    lpips_fn = None
    if config.eval.lpips_net:
      from mfsample import metrics as metrics_lib
      lpips_fn = metrics_lib.make_lpips(config.eval.lpips_net)
    wd.write_config()
    result, kind = _train_or_fit(config, dataset, train_views, wd.file("checkpoints"))
    model, settings = result.state.model, result.setup.step_config.settings
    wd.write_json("train_log.json", result.history, indent=2)
    if kind == "joint" and config.eval.export_ply and wd.writes:
      from mfsample.data.ply import export_ply
      export_ply(wd.file("point_cloud.ply"), model)

    # One z (M = next_views.samples) for the test maps and the candidates; every render
    # starts from the training's budget (renders of one size share the compiled code).
    z = sample_z(model, int(config.next_views.samples), seed=int(config.next_views.z_seed))
    budgets = Budgets().replace(eval=settings, score=settings, mean=settings)
    test = _test_maps(config, model, dataset, z, settings, lpips_fn, wd)
    warnings_ = _posthoc_warnings(config, kind, test["metrics"])
    proposal = _propose(config, model, dataset, train_idx, candidates, center, z, budgets, wd)
    wd.write_json("next_views.json", proposal["record"], indent=2)
    # Files only: the other processes of a multi-process run have nothing to compute here.
    files = {}
    if wd.writes:
      wd.stage("writing the proposals and the uncertainty per Gaussian for viewers")
      files, budgets = _viewer_files(config, model, dataset, proposal, z, budgets, wd)
    if config.next_views.figure and wd.writes:
      from mfsample.your_data.figure import next_views_figure

      shown = min(4, len(dataset.test))
      next_views_figure(
          wd.file("next_views.png"),
          train_centers=np.asarray(train_views.cameras.center),
          candidate_centers=np.asarray(proposal["cameras"].center), u=proposal["u"],
          top=proposal["top"], top_renders=proposal["renders"], top_maps=proposal["maps"],
          top_images=proposal["images"], test_renders=test["renders"][:shown],
          test_maps=test["maps"][:shown],
          top_names=[proposal["record"]["names"][i] for i in proposal["top"]],
          test_names=dataset.test.names[:shown] if dataset.test.names else None,
          title=f"{_scene_name(config)}: {kind} uncertainty, "
                f"{_count(len(train_views), 'training view')}, next "
                f"{len(proposal['top'])} of {_count(len(proposal['u']), 'candidate')}")

    record = proposal["record"]
    results = {
        "scene": _scene_name(config), "kind": kind, "steps": int(result.state.step),
        "train_seconds": result.train_seconds, "live_gaussians": model.num_live,
        "num_train_views": len(train_views), "num_test_views": len(dataset.test),
        "test": test["metrics"],
        "next_views": {key: record[key] for key in (
            "candidates", "num_candidates", "samples", "score_downscale", "rho_u_error",
            "rho_u_angle", "rho_error_angle")},
        "top_k": [{"rank": t["rank"], "name": t["name"], "u": t["u"]}
                  for t in record["top_k"]],
        "files": files,
        "warnings": warnings_,
        "seconds_this_call": time.perf_counter() - t0,
    }
    # Read back only while what it points to is what this call wrote.
    wd.write_json("results.json", results, indent=2, files=(
        "train_log.json", "point_cloud.ply", "test", "next_views.json", "next_views",
        "uncertainty_ply", "next_views.png"))
    return results


def _posthoc_warnings(config, kind, metrics):
  """[message] when a post-hoc model does not reproduce its capture (test PSNR below
  `posthoc.min_psnr`), each also issued as a warning."""
  if kind != "posthoc" or not metrics["psnr"] < float(config.posthoc.min_psnr):
    return []
  message = (f"the model of posthoc.ply = {config.posthoc.ply!r} renders the test views at "
             f"{metrics['psnr']:.1f} dB PSNR, below posthoc.min_psnr = "
             f"{float(config.posthoc.min_psnr):g}: it does not reproduce this capture (a "
             "model of another capture or world, or data.background = "
             f"{tuple(config.data.background)} is not the one it was trained on), and its "
             "U says little about it")
  warnings.warn(message, stacklevel=3)
  return [message]


def _count(n, noun):
  return f"{n} {noun}{'' if n == 1 else 's'}"


def _scene_name(config):
  return data_spec(config.data).name


def _train_or_fit(config, dataset, train_views, checkpoint_dir):
  """(`TrainResult`, "joint" | "posthoc") with checkpoints in `checkpoint_dir`."""
  from mfsample.data import ply
  from mfsample.train.config import recipe, train_spec
  from mfsample.train.loop import run_training
  from mfsample.train.posthoc import run_b_hat_fit

  settings, init = train_spec(config)
  extent = settings.extent
  if extent is None:  # 3DGS's, from the training cameras
    extent = datasets.scene_extent(train_views.cameras)
  seed = int(config.seed)
  kw = dict(seed=seed, extent=extent, checkpoint_dir=checkpoint_dir,
            checkpoint_every=config.train.checkpoint_every,
            keep_checkpoints=config.train.keep_checkpoints, progress=config.train.progress,
            record={"job": JOB.name})
  if config.posthoc.ply:
    path = resolve_path(config.posthoc.ply)
    # The model as stored: its SH degree is the file's; the fit's length is posthoc.steps.
    plan = recipe(config, extent=extent, init=init.replace(
        init_from="ply", ply_path=str(path), sh_degree=ply.sh_degree_of(ply.load_ply(path))))
    model = plan.initial_model(seed=seed, bounds=dataset.bounds)
    return run_b_hat_fit(model, train_views,
                         settings.replace(num_steps=int(config.posthoc.steps)), **kw), "posthoc"
  plan = recipe(config, extent=extent)
  model = plan.initial_model(seed=seed, bounds=dataset.bounds, points=dataset.points)
  return run_training(model, train_views, settings, **kw), "joint"


def _test_maps(config, model, dataset, z, settings, lpips_fn, wd):
  """Renders, U maps and metrics of every test view, with a progress bar; written to the
  workdir's `test/`. Returns {"metrics", "renders", "maps"}."""
  from mfsample.train import evaluate as eval_lib

  per_view = []
  bar = wd.progress(len(dataset.test), "test views")
  for i in range(len(dataset.test)):
    interrupts.check(f"at test view {i}")
    per_view.append(eval_lib.evaluate(model, dataset.test.subset([i]),
                                      background=dataset.background, settings=settings,
                                      lpips_fn=lpips_fn, uncertainty_z=z))
    bar.update(1)
  bar.close()
  merged = eval_lib.EvalResult(
      metrics={}, per_view={key: [e.per_view[key][0] if e.per_view[key] else None
                                  for e in per_view] for key in ("psnr", "ssim", "lpips")},
      images=np.concatenate([e.images for e in per_view]),
      uncertainty=np.concatenate([e.uncertainty for e in per_view]))
  if wd.writes:
    eval_lib.save_images(wd.file("test"), merged, dataset.test,
                         num=int(config.eval.save_images))
  u = merged.uncertainty.reshape(len(per_view), -1).sum(axis=1)
  metrics = {"psnr": float(np.mean(merged.per_view["psnr"])),
             "ssim": float(np.mean(merged.per_view["ssim"])),
             "lpips": (float(np.mean(merged.per_view["lpips"])) if lpips_fn else None),
             "mean_u": float(np.mean(u)), "samples": int(z.shape[0]),
             "per_view": {"name": list(dataset.test.names), "u": u.tolist(),
                          **merged.per_view}}
  wd.write_json("test/metrics.json", metrics, indent=2)
  return {"metrics": {k: v for k, v in metrics.items() if k != "per_view"},
          "renders": merged.images, "maps": merged.uncertainty}


def _candidates(config, dataset, train_idx, unused_idx, center):
  """(cameras [B], images [B, H, W, 3] or None, names) of the candidates."""
  from mfsample.your_data.candidates import sphere_candidates

  nv = config.next_views
  if nv.candidates == "unused":
    names = [dataset.train.names[i] for i in unused_idx] if dataset.train.names else [
        f"train_{i}" for i in unused_idx]
    return (dataset.train.cameras[unused_idx], np.asarray(dataset.train.images)[unused_idx],
            names)
  cameras = sphere_candidates(dataset.train.cameras[train_idx], center, int(nv.sphere_views))
  return cameras, None, [f"sphere_{i:03d}" for i in range(len(cameras))]


def _propose(config, model, dataset, train_idx, candidates, center, z, budgets, wd):
  """U of every candidate (`candidates`: `_candidates`; progress bar), the top k with their
  renders and U maps, and the record. With candidate images, the error of the mean render
  there and Spearman's rho of U against it (`mfsample.planning.u_error`: U at the scoring
  size, the squared error at full size; rho with the angle to the nearest training view
  beside it)."""
  from mfsample.planning.u_error import u_against_error
  from mfsample.selection import top_k
  from mfsample.your_data.export import preview

  nv = config.next_views
  cameras, images, names = candidates
  num = len(cameras)
  bar = wd.progress(num, "candidates")
  ranking = u_against_error(
      model, cameras, z, background=dataset.background, images=images,
      train_cameras=dataset.train.cameras[train_idx] if images is not None else None,
      center=center, score_downscale=int(nv.score_downscale),
      score_settings=budgets.get("score"), mean_settings=budgets.get("mean"), batch=16,
      on_batch=lambda done: bar.update(done - bar.n))
  bar.close()
  budgets = budgets.replace(score=ranking.score_settings, mean=ranking.mean_settings)
  top = top_k(ranking.u, int(nv.k))
  # The proposals' mean renders and U maps at full size (written again by _viewer_files).
  renders, maps, u_maps, settings = preview(model, cameras[top], z, settings=budgets.get("eval"),
                                            background=dataset.background)
  budgets = budgets.replace(eval=settings)
  w2c = np.asarray(cameras.world_to_camera, np.float64)
  record = {"candidates": nv.candidates, "samples": int(z.shape[0]),
            "score_downscale": int(nv.score_downscale), "rho_u_error": ranking.rho_u_error,
            "rho_u_angle": ranking.rho_u_angle, "rho_error_angle": ranking.rho_error_angle,
            "num_candidates": num, "u": ranking.u.tolist(), "names": names, "top_k": [{
                "rank": rank + 1, "index": int(i), "name": names[i], "u": float(ranking.u[i]),
                "error": None if images is None else float(ranking.error[i]),
                "world_to_camera": w2c[i].tolist(),
                "intrinsics": {"fx": float(cameras.fx[i]), "fy": float(cameras.fy[i]),
                               "cx": float(cameras.cx[i]), "cy": float(cameras.cy[i]),
                               "width": int(cameras.width), "height": int(cameras.height)},
            } for rank, i in enumerate(top)]}
  return {"record": record, "u": ranking.u, "top": top, "cameras": cameras,
          "images": None if images is None else images[top],
          "renders": renders, "maps": maps, "map_sums": u_maps}


def _viewer_files(config, model, dataset, proposal, z, budgets, wd):
  """The proposals as cameras in viewers' formats with a preview each (`next_views/`), and the
  model's uncertainty per Gaussian over the candidates as .ply files (`uncertainty_ply/`).

  Returns:
    ({"next_views": folder, "uncertainty_ply": [files]}, relative to the workdir; budgets).
  """
  from mfsample.gaussian_uncertainty import gaussian_uncertainty
  from mfsample.your_data.export import export_next_views
  from mfsample.your_data.uncertainty_ply import write_uncertainty_plys

  top = np.asarray(proposal["top"], int)
  names = [f"{rank + 1:02d}_{proposal['record']['names'][i]}" for rank, i in enumerate(top)]
  # A capture's files speak of its tools' world (nerfstudio's applied_transform), so that its
  # tools see one world.
  applied = dataset.world_transform
  background = jnp.asarray(dataset.background, jnp.float32)
  _, settings = export_next_views(
      wd.file("next_views"), model, proposal["cameras"][top], z, settings=budgets.get("eval"),
      background=background, names=names, images=proposal["images"],
      applied_transform=applied,
      previews=(proposal["renders"], proposal["maps"], proposal["map_sums"]))
  per_gaussian = gaussian_uncertainty(model, proposal["cameras"], z, settings=settings,
                                      background=background)
  plys = write_uncertainty_plys(wd.file("uncertainty_ply"), model, per_gaussian)
  files = {"next_views": "next_views",
           "uncertainty_ply": [os.path.relpath(p, wd.path) for p in plys]}
  return files, budgets.replace(eval=settings)


def report(results, workdir):
  """What `experiments/next_views.py` prints: test quality, the proposals, and how far the
  ranking follows the model's error on this capture."""
  lines = [f"{results['kind']} uncertainty of {results['scene']}: test PSNR "
           f"{results['test']['psnr']:.2f} dB, mean U {results['test']['mean_u']:.4g}"]
  lines += [f"  warning: {w}" for w in results.get("warnings", ())]
  lines += [f"  next view {t['rank']}: {t['name']} (U = {t['u']:.4g})" for t in results["top_k"]]
  nv = results["next_views"]
  if nv["candidates"] == "unused":  # candidates with images: U against the model's error
    rho = nv["rho_u_error"]
    lines.append("  Spearman rho of U against the model's error over the candidates: "
                 + (f"{rho:.2f}" if rho is not None else
                    f"undefined ({nv['num_candidates']} candidate(s); it needs 3 or more whose "
                    "U and error are not all equal)"))
  files = results.get("files", {})
  if files:
    lines.append(f"  viewers: {files['next_views']}/ (cameras.json for SuperSplat, "
                 "transforms.json and camera_path.json for nerfstudio, COLMAP text), "
                 + ", ".join(files["uncertainty_ply"]))
  lines.append(f"written to {workdir}")
  return "\n".join(lines)


# Fields that change only how a call looks or how fast it goes: a later call may differ.
FREE_FIELDS = ("train.progress", "next_views.figure") + speed_only_fields()
JOB = jobs.Job("next views", "next_views", run_next_views, validate, FREE_FIELDS,
               ("results.json", "checkpoints"), report=report, progress_field="train.progress")
