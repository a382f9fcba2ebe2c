"""The model a training job starts from: `InitSettings.init_from`.

* "random": `init_points` points uniform in the scene box (3DGS's start without SfM, NeRF
  Synthetic's usual one), near-grey colours;
* "points": the dataset's sparse SfM points with their colours (3DGS's start on real
  captures; COLMAP and nerfstudio data);
* "ply": the Gaussians of a trained 3DGS model (`ply_path`), kept exactly as stored. With the
  mean frozen this is post-hoc uncertainty (`mfsample.train.posthoc`); trained jointly, it
  fine-tunes the model as a stochastic field.

Every start gets fresh B_hat entries (`mfsample.model.init_b_hat`). Everything random is a
function of the run's seed, so a resumed run rebuilds the same start as its template.
"""

from typing import NamedTuple

import jax
import numpy as np

from mfsample.model import init_model, model_from_mean
from mfsample.samplers import SamplerSpec
from mfsample.train.settings import InitSettings, TrainSettings


class Recipe(NamedTuple):
  """A kind of model a job trains: its training, its start and its sampler, all typed.

  Attributes:
    settings: `TrainSettings`.
    init: `InitSettings` (the start).
    spec: the model's `SamplerSpec` (its centres' bound in world units of `extent`).
    extent: the scene extent (world units) the spec and the settings are meant for.
  """

  settings: TrainSettings
  init: InitSettings
  spec: SamplerSpec
  extent: float

  def initial_model(self, *, seed, bounds, points=None):
    """The step-0 `Model` for `seed` (`initial_model`)."""
    return initial_model(self.init, self.spec, self.settings.b_hat_init_scales(self.extent),
                         seed=seed, bounds=bounds, points=points)

  def densifies(self):
    """Whether a run densifies (and so changes shape) within its steps."""
    return self.settings.densify.active_within(self.settings.num_steps)

  def with_render(self, render):
    """The recipe whose training renders start from `render` (a budget that sufficed), or
    itself when `render` is None."""
    if render is None:
      return self
    return self._replace(settings=self.settings.replace(render=render))


def model_key(seed):
  """The PRNG key of a run's initial model (colours, B_hat entries and signs): the first half
  of the seed's key (the second seeds the steps, `loop.init_state`)."""
  return jax.random.split(jax.random.PRNGKey(int(seed)))[0]


def initial_model(init: InitSettings, spec: SamplerSpec, init_scales, *, seed, bounds,
                  points=None):
  """The step-0 `Model` of a run.

  Args:
    init: `InitSettings`.
    spec: the model's `SamplerSpec`.
    init_scales: {group: scale} of the fresh raw B_hat entries.
    seed: the run's integer seed.
    bounds: (low [3], high [3]) box of the random initial points.
    points: the dataset's `mfsample.data.PointCloud`, or None.
  """
  key = model_key(seed)
  kw = dict(spec=spec, init_scales=init_scales)
  if init.init_from == "random":
    rng = np.random.default_rng([int(seed), 0])
    low, high = (np.broadcast_to(np.asarray(b, np.float64), (3,)) for b in bounds)
    xyz = rng.uniform(low, high, (init.init_points, 3))
    return init_model(key, xyz, sh_degree=init.sh_degree, init_opacity=init.init_opacity, **kw)
  if init.init_from == "points":
    if points is None or len(points) == 0:
      raise ValueError("init_from = 'points' needs a dataset with a sparse point cloud (a "
                       "COLMAP or nerfstudio capture)" + (", and this one has no points"
                                                          if points is not None else ""))
    from mfsample.data import PointCloud

    points = PointCloud(*points).validate()  # colours on another scale: refused, not clipped
    return init_model(key, np.asarray(points.xyz, np.float64), sh_degree=init.sh_degree,
                      init_opacity=init.init_opacity,
                      colors=np.asarray(points.rgb, np.float64), **kw)
  from mfsample.data import ply, resolve_path

  path = resolve_path(init.ply_path)
  mean = ply.load_ply(path)
  degree = ply.sh_degree_of(mean)
  if degree != init.sh_degree:
    raise ValueError(f"{path} holds SH degree {degree} but the model's sh_degree is "
                     f"{init.sh_degree}: set it to {degree}")
  return model_from_mean(key, mean, **kw)
