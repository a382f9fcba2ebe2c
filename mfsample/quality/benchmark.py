"""The AUSE benchmark (the paper's Table 5): pure steps and a resumable loop.

For every scene, seed and model (one per sampler of `ause.samplers`, and a deterministic
one for the baselines), all trained on the same views of the forward-facing arc:

1. train the model (`config.train`, its sampler replaced; `planning.training.train_on_views`);
2. at every test view, render the mean (colour, coverage, expected depth), take the depth
   error and its mask, and each method's per-pixel map (`maps`); the baseline "posthoc"
   first fits B_hat to the deterministic model with its mean frozen (`fit_posthoc`), so its
   maps are judged against the very error of the model they were fitted to;
3. AUSE of every map against its model's depth error (`mfsample.metrics.ause`, MAE and RMSE),
   and, as the floor of no information, of a constant map.

Each (scene, seed, model) is written as soon as it is done (`ause/<scene>-seed<s>-<model>`:
a JSON record and the maps as .npz for the figures), so a killed run resumes without redoing
finished models.
"""

import dataclasses
import os
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import interrupts, metrics
from mfsample.baselines import activenerf, fisher
from mfsample.mean_render import render_mean
from mfsample.planning import training
from mfsample.quality import arc as arc_lib
from mfsample.quality import maps as maps_lib
from mfsample.renderer.budget import render_with_budget
from mfsample.samplers import STOCHASTIC_KINDS, sample_z

POSTHOC = "posthoc"
BASELINES = ("fisher", "activenerf", POSTHOC)
DETERMINISTIC = "deterministic"
# The maps of the baseline "posthoc": Ours' two maps of the fitted field.
POSTHOC_MAPS = ("posthoc_colour", "posthoc_depth")


def parse_sampler(flag):
  """"kind" or "kind:k" -> (kind, k or None), kind one of `mfsample.samplers.STOCHASTIC_KINDS`."""
  kind, _, rank = str(flag).partition(":")
  if kind not in STOCHASTIC_KINDS:
    raise ValueError(f"sampler {flag!r}: the kind must be one of {', '.join(STOCHASTIC_KINDS)}")
  if rank and (not rank.isdigit() or int(rank) < 1):
    raise ValueError(f"sampler {flag!r}: the rank after ':' must be an integer >= 1")
  return kind, (int(rank) if rank else None)


def model_names(config):
  """The models of a scene and seed: the samplers, then the baselines' deterministic one."""
  names = list(config.ause.samplers)
  if config.ause.baselines:
    names.append(DETERMINISTIC)
  return names


def model_recipe(train_config, name, prefix="config.train"):
  """The `Recipe` of model `name` (a sampler flag or "deterministic") of the models'
  training config: its sampler's kind (and rank) replaced."""
  from mfsample.train.config import recipe

  base = recipe(train_config, prefix=prefix)
  if name == DETERMINISTIC:
    return base._replace(spec=dataclasses.replace(base.spec, kind=DETERMINISTIC))
  kind, rank = parse_sampler(name)
  return base._replace(spec=dataclasses.replace(base.spec, kind=kind,
                                                rank=base.spec.rank if rank is None else rank))


def unit_name(scene, seed, name):
  """The file stem of one (scene, seed, model) in `ause/`."""
  return f"{scene}-seed{int(seed)}-{name.replace(':', '')}"


def method_keys(config, name):
  """The maps a model yields: "colour" and "depth" (Ours' samplers), or the baselines'
  ("posthoc" yields `POSTHOC_MAPS`)."""
  if name != DETERMINISTIC:
    return ["colour", "depth"]
  keys = []
  for baseline in config.ause.baselines:
    keys += list(POSTHOC_MAPS) if baseline == POSTHOC else [baseline]
  return keys


def fit_posthoc(config, model, train_views, seed, settings=None):
  """B_hat fitted to a trained deterministic `model` with its mean frozen (post-hoc U).

  The user's path for a pretrained model: the model is written as a 3DGS .ply
  (`data.ply.export_ply`), read back as the mean of a stochastic field of
  `ause.posthoc_sampler`, and `mfsample.train.posthoc.run_b_hat_fit` fits its B_hat for
  `ause.posthoc_steps` steps on its training views, with the models' training settings
  otherwise (loss, B_hat learning rates and bounds; lambda as `posthoc.posthoc_settings`
  chooses).

  Returns:
    `mfsample.train.TrainResult` (`state.model`: the field, its mean `model`'s live
    Gaussians bit for bit; `train_seconds`: the fit's wall-clock, compilation included).
  """
  from mfsample.data.ply import export_ply, load_ply, sh_degree_of
  from mfsample.train.posthoc import run_b_hat_fit

  plan = model_recipe(config.train, config.ause.posthoc_sampler)
  with tempfile.TemporaryDirectory(prefix="posthoc_") as tmp:
    path = os.path.join(tmp, "point_cloud.ply")
    export_ply(path, model)
    plan = plan._replace(init=plan.init.replace(init_from="ply", ply_path=path,
                                                sh_degree=sh_degree_of(load_ply(path))))
    start = plan.initial_model(seed=int(seed), bounds=(np.zeros(3), np.ones(3)))
  return run_b_hat_fit(start, train_views,
                       plan.with_render(settings).settings.replace(
                           num_steps=int(config.ause.posthoc_steps)),
                       seed=int(seed), extent=plan.extent)


def same_mean(model, fitted):
  """Whether `fitted`'s live Gaussians are `model`'s, parameter for parameter, bit for bit."""
  live, n = np.asarray(model.mask), int(fitted.num_live)
  if set(model.params.mean) != set(fitted.params.mean) or int(live.sum()) != n:
    return False
  return all(np.array_equal(np.asarray(v)[live], np.asarray(fitted.params.mean[g])[:n])
             for g, v in model.params.mean.items())


def ause_of_model(config, name, trained, train_views, test_views, seed):
  """Depth errors, every method's maps and their AUSE at the test views of one model.

  Args:
    config: the uncertainty-quality config.
    name: the model's name (a sampler flag or "deterministic").
    trained: `planning.training.Trained`.
    train_views: `Views` it was trained on (FisherRF's H(train), ActiveNeRF's fit).
    test_views: `Views` with alphas and depths.
    seed: the model's seed (probe and fit randomness).

  Returns:
    (json-able record, {array name: [V, ...] numpy}: the maps, errors and masks).
  """
  model = trained.model
  bg = jnp.asarray(config.data.background, jnp.float32)
  settings = trained.settings
  m = config.mask
  methods = method_keys(config, name)
  renders, errors, masks = [], [], []
  for i in range(len(test_views)):
    out, settings = render_with_budget(render_mean, settings, model, test_views.cameras[i],
                                       bg)
    err, mask = maps_lib.depth_error(out.expected_depth(), out.alpha, test_views.depths[i],
                                     test_views.alphas[i], true_alpha_min=float(m.true_alpha_min),
                                     model_alpha_min=float(m.model_alpha_min))
    renders.append(np.asarray(jnp.clip(out.rgb, 0.0, 1.0)))
    errors.append(err)
    masks.append(mask)
  maps, settings, extra = _method_maps(config, name, model, settings, train_views, test_views,
                                       seed)

  views = []
  for i in range(len(test_views)):
    entry = {"psnr": float(metrics.psnr(renders[i], test_views.images[i])),
             "mask_fraction": float(masks[i].mean()),
             "depth_mae": float(errors[i][masks[i]].mean()) if masks[i].any() else None,
             "ause": {}}
    if masks[i].any():
      for method in methods + ["constant"]:
        u = maps[method][i] if method != "constant" else np.zeros_like(errors[i])
        entry["ause"][method] = {measure: metrics.ause(u, errors[i], masks[i], measure=measure)
                                 for measure in metrics.AUSE_MEASURES}
    views.append(entry)
  record = {"model": name, "methods": methods, "views": views,
            "num_live": int(model.num_live), "train_seconds": float(trained.seconds),
            "data_loss": float(trained.loss), **extra}
  arrays = {"render": np.stack(renders).astype(np.float32),
            "depth_error": np.stack(errors).astype(np.float32), "mask": np.stack(masks),
            **{f"map_{k}": np.stack(maps[k]).astype(np.float32) for k in methods}}
  return record, arrays


def _sample_maps(config, model, settings, test_views, prefix=""):
  """Ours' colour and depth maps of a stochastic field at the test views, under the keys
  `prefix + "colour"` and `prefix + "depth"`, and the render settings that sufficed."""
  bg = jnp.asarray(config.data.background, jnp.float32)
  z = sample_z(model, int(config.ause.samples), seed=int(config.ause.z_seed))
  out = {prefix + "colour": [], prefix + "depth": []}
  for i in range(len(test_views)):
    res, settings = render_with_budget(maps_lib.sample_maps, settings, model,
                                       test_views.cameras[i], z, bg)
    out[prefix + "colour"].append(np.asarray(res.colour))
    out[prefix + "depth"].append(np.asarray(res.depth))
  return out, settings


def _method_maps(config, name, model, settings, train_views, test_views, seed):
  """{method: [per test view [H, W] numpy]}, the render settings that sufficed, and what the
  record keeps of the post-hoc fit ({"posthoc": {...}} or {})."""
  if name != DETERMINISTIC:
    out, settings = _sample_maps(config, model, settings, test_views)
    return out, settings, {}
  bg = jnp.asarray(config.data.background, jnp.float32)
  out, extra = {}, {}
  key = jax.random.fold_in(jax.random.PRNGKey(int(seed)), 40)
  if "fisher" in config.ause.baselines:
    f = config.fisher
    groups = tuple(g for g in f.groups if g in model.params.mean)
    scores, settings = fisher.fisher_scores(
        model, train_views.cameras, test_views.cameras, key, settings=settings, background=bg,
        num_probes=1, train_probes=int(f.train_probes), reg=float(f.reg), groups=groups)
    out["fisher"] = []
    for i in range(len(test_views)):
      (u, _), settings = render_with_budget(
          fisher.fisher_pixel_variance, settings, model, test_views.cameras[i],
          scores.h_train, jax.random.fold_in(key, i), float(f.reg), background=bg,
          num_probes=int(f.pixel_probes), groups=groups, stats_of=lambda o: o[1])
      out["fisher"].append(np.asarray(u))
  if "activenerf" in config.ause.baselines:
    a = config.activenerf
    vmodel, _ = activenerf.fit_variance(
        model, train_views, settings=settings, background=bg, steps=int(a.steps),
        lr=float(a.lr), prior_var=float(a.prior_var), beta_min=float(a.beta_min),
        prior_weight=float(a.prior_weight), seed=int(seed))
    out["activenerf"] = []
    for i in range(len(test_views)):
      (beta2, _), settings = render_with_budget(maps_lib.activenerf_map, settings, vmodel,
                                                test_views.cameras[i], stats_of=lambda o: o[1])
      out["activenerf"].append(np.asarray(beta2))
  if POSTHOC in config.ause.baselines:
    fit = fit_posthoc(config, model, train_views, seed, settings=settings)
    field = fit.state.model
    maps, settings = _sample_maps(config, field, fit.setup.step_config.settings, test_views,
                                  prefix=POSTHOC + "_")
    out.update(maps)
    extra[POSTHOC] = {"sampler": str(config.ause.posthoc_sampler),
                      "steps": int(fit.state.step), "seconds": float(fit.train_seconds),
                      "mean_unchanged": same_mean(model, field)}
  return out, settings, extra


def _complete(record, config):
  """Whether a stored record holds every map the config asks of its model."""
  return set(method_keys(config, record["model"])) <= set(record["methods"])


def run_ause(config, wd, bar=None):
  """Runs (or resumes) the AUSE benchmark of `config` in the workdir's `ause/`.

  A unit (scene, seed, model) is its record `ause/<unit>.json` and its arrays
  `ause/<unit>.npz`; one that is missing, damaged (reported) or lacks a map the config asks
  for is computed again.

  Args:
    config: the uncertainty-quality config.
    wd: the `mfsample.jobs.Workdir`.
    bar: optional progress bar (one step per unit).

  Returns:
    {"records": list of records (each with "scene" and "seed"), "views": {scene: (train
    `Views`, test `Views`)}, "arrays": {(scene, seed, model): the unit's arrays}}.
  """
  a = config.ause
  train_idx, test_idx = arc_lib.split(config.data.arc.num_views)
  records, scene_views, unit_arrays = [], {}, {}
  for scene in a.scenes:
    views, bounds = arc_lib.arc_views(config.data, scene)
    train_views, test_views = views.subset(train_idx), views.subset(test_idx)
    scene_views[scene] = (train_views, test_views)
    for seed in a.seeds:
      for name in model_names(config):
        stem = os.path.join("ause", unit_name(scene, seed, name))
        record = wd.read_json(stem + ".json")
        arrays = None
        if record is not None and _complete(record, config):
          arrays = wd.load_arrays(stem + ".npz", keys=_array_keys(config, name))
        if arrays is None:
          interrupts.check(f"before {stem}")
          if bar is not None:
            bar.set_postfix_str(f"{scene}, seed {seed}, {name}")
          t0 = time.perf_counter()
          trained = training.train_on_views(model_recipe(config.train, name), train_views,
                                            seed=int(seed), bounds=bounds,
                                            pad_to=len(train_views))
          record, arrays = ause_of_model(config, name, trained, train_views, test_views,
                                          int(seed))
          record.update(scene=scene, seed=int(seed), train_views=train_idx.tolist(),
                        test_views=test_idx.tolist(), seconds=time.perf_counter() - t0)
          wd.save_arrays(stem + ".npz", **arrays)
          wd.write_json(stem + ".json", record, files=(stem + ".npz",))  # last: marks it done
        records.append(record)
        unit_arrays[(scene, int(seed), name)] = arrays
        if bar is not None:
          bar.update(1)
  return {"records": records, "views": scene_views, "arrays": unit_arrays}


def _array_keys(config, name):
  """The arrays a unit of model `name` holds."""
  return ("render", "depth_error", "mask") + tuple(f"map_{k}" for k in method_keys(config,
                                                                                    name))
