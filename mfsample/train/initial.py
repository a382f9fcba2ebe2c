"""The model a training run starts from: `config.model.init_from`.

* "random": `model.init_points` points uniform in the scene box (3DGS's start without SfM,
  NeRF Synthetic's usual one), near-grey colours;
* "points": the dataset's sparse SfM points with their colours (3DGS's start on real
  captures; `data.kind = "colmap"`);
* "ply": the Gaussians of a trained 3DGS model (`model.ply_path`), kept exactly as stored.
  With the mean frozen this is post-hoc uncertainty (`mfsample.train.posthoc`); trained
  jointly, it fine-tunes the model as a stochastic field.

Every start gets fresh B_hat entries (`mfsample.model.init_spread`). Everything random is
a function of the run's seed, so a resumed run rebuilds the same start as its template.
"""

import numpy as np

from mfsample.model import init_model, model_from_mean

INIT_FROM = ("random", "points", "ply")


def initial_model(config, setup, bounds, points, key):
  """The step-0 `Model` of a run.

  Args:
    config: training config (`model.init_from`, `model.init_points`, `model.ply_path`,
      `model.sh_degree`, `model.init_opacity`).
    setup: `TrainSetup` (seed, sampler spec, B_hat scales).
    bounds: (low [3], high [3]) box of the random initial points.
    points: the dataset's `mfsample.data.colmap.PointCloud`, or None.
    key: PRNG key of the model (colours, B_hat entries and signs).
  """
  init_from = config.model.get("init_from", "random")
  sh_degree = int(config.model.sh_degree)
  kw = dict(spec=setup.spec, init_scales=setup.init_scales)
  if init_from == "random":
    rng = np.random.default_rng([setup.seed, 0])
    low, high = (np.asarray(b, np.float64) for b in bounds)
    xyz = rng.uniform(low, high, (int(config.model.init_points), 3))
    return init_model(key, xyz, sh_degree=sh_degree, init_opacity=config.model.init_opacity,
                      **kw)
  if init_from == "points":
    if points is None or len(points) == 0:
      raise ValueError("config.model.init_from = 'points' needs a dataset with a sparse point "
                       f"cloud (data.kind = 'colmap'), got data.kind = "
                       f"{config.data.get('kind')!r}" + (" with no points" if points is not None
                                                         else ""))
    return init_model(key, np.asarray(points.xyz, np.float64), sh_degree=sh_degree,
                      init_opacity=config.model.init_opacity,
                      colors=np.clip(np.asarray(points.rgb, np.float64), 0.0, 1.0), **kw)
  if init_from == "ply":
    from mfsample.data import ply

    path = config.model.get("ply_path") or ""
    if not path:
      raise ValueError("config.model.init_from = 'ply' needs config.model.ply_path, the "
                       "3DGS point_cloud.ply to start from")
    from mfsample.data import resolve_path

    path = resolve_path(path)
    mean = ply.load_ply(path)
    degree = ply.sh_degree_of(mean)
    if degree != sh_degree:
      raise ValueError(f"{path} holds SH degree {degree} but config.model.sh_degree = "
                       f"{sh_degree}: set it to {degree}")
    return model_from_mean(key, mean, **kw)
  raise ValueError(f"config.model.init_from = {init_from!r}: must be one of "
                   f"{', '.join(repr(c) for c in INIT_FROM)}")
