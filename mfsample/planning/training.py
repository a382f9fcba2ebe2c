"""A thin adapter over `mfsample.train` for the planning protocol.

The protocol trains a fresh model after every added view. Calling
`mfsample.train.run_training` on 1, 2, ..., 9 views would compile the jitted training step nine
times per model kind, because the step takes the stacked training images as an argument
and their leading axis grows. `train_on_views` instead pads the images to a fixed number
of slots (`pad_to`) and draws the step's view only among the real ones, with the training
code's own loop (`run_training(..., num_views=n)`), so one compilation serves every round:
set-up, initial state, the jitted step and budget growth on overflow are the training
module's.

For the same reason the recipe must fix what would otherwise change with the views and
sits in the step's static settings: the extent and `loss.volume_weight` (the authors use
1 / number of views; the planning configs state the constant they use instead).
`train_on_views` can also continue from a previous state on a larger view set, for the
paper's reading of the protocol (one training run, a camera added every so many steps).
A model that densifies changes shape as it trains, so padding saves nothing: rounds and
final models with densification (`densify.start < num_steps`) go through
`train_densified`, which is `mfsample.train.run_training` itself (one compilation per view count
and capacity), with the authors' volume weight 1 / number of views allowed.
"""

from typing import NamedTuple

import numpy as np

from mfsample.train.initial import Recipe
from mfsample.train.loop import TrainResult, run_training


class Trained(NamedTuple):
  """A trained model.

  Attributes:
    model: `mfsample.model.Model`.
    settings: `RenderSettings` whose budget sufficed (reuse it to avoid regrowth).
    seconds: wall-clock of the training loop (compilation included).
    loss: the last step's data loss.
    state: the final `mfsample.train.TrainState` (to continue training from).
  """

  model: object
  settings: object
  seconds: float
  loss: float
  state: object = None


def _box(bounds):
  low, high = bounds
  return np.broadcast_to(np.asarray(low, np.float64), (3,)), np.broadcast_to(
      np.asarray(high, np.float64), (3,))


def train_on_views(recipe: Recipe, views, *, seed, bounds, pad_to, render=None, state=None,
                   stop_at=None, points=None) -> Trained:
  """Trains a model of `recipe` on `views` (no densification): fresh, or continuing from
  `state`.

  The schedules (learning-rate decay, the volume term's last steps) follow
  `recipe.settings.num_steps`; `stop_at` ends the call earlier, so that training can
  continue later from the returned state on more views (the paper's text: one run, a camera
  added every so many steps).

  Args:
    recipe: `Recipe` whose settings fix `loss.volume_weight` (see the module docstring).
    views: the training `Views` (1 <= len(views) <= pad_to).
    seed: seeds the initial point cloud, B_hat signs, the z sequence and the view order.
    bounds: (low, high) box of the random initial point cloud.
    pad_to: number of image slots of the jitted step (the protocol's maximum views).
    render: optional `RenderSettings` to start from (a budget that sufficed before).
    state: optional `TrainState` to continue from (default: a fresh initial state).
    stop_at: stop when this many steps are done in total (default: `num_steps`).
    points: the pool's SfM `PointCloud`, for `init_from = "points"`.

  Returns:
    `Trained`.
  """
  n = len(views)
  if not 1 <= n <= pad_to:
    raise ValueError(f"need 1 <= len(views) <= pad_to, got {n} views and pad_to={pad_to}")
  if recipe.settings.loss.volume_weight is None:
    raise ValueError("train_on_views needs loss.volume_weight set: otherwise the jitted step "
                     "recompiles for every view count")
  if recipe.densifies():
    raise ValueError("train_on_views trains padded, fixed-shape models without "
                     "densification: set densify.start >= train.num_steps, or use "
                     "train_densified")
  recipe = recipe.with_render(render)
  model = recipe.initial_model(seed=seed, bounds=_box(bounds), points=points) \
      if state is None else state.model
  slots = np.minimum(np.arange(pad_to), n - 1)  # padding repeats the last view, never drawn
  padded = views.subset(slots).replace(names=())  # (a repeated name would not name a view)
  result = run_training(model, padded, recipe.settings, seed=seed,
                        extent=recipe.extent, state=state, stop_at=stop_at, num_views=n)
  return _trained(result, with_state=True)


def _trained(result: TrainResult, with_state=False) -> Trained:
  loss = result.history[-1]["data_loss"] if result.history else float("nan")
  return Trained(result.state.model, result.setup.step_config.settings, result.seconds, loss,
                 result.state if with_state else None)


def train_densified(recipe: Recipe, views, *, seed, bounds, render=None,
                    points=None) -> Trained:
  """Trains a model of `recipe` on `views` with `mfsample.train.run_training` as it is,
  densification included (the final models' path; the rounds' when they densify)."""
  recipe = recipe.with_render(render)
  model = recipe.initial_model(seed=seed, bounds=_box(bounds), points=points)
  return _trained(run_training(model, views, recipe.settings, seed=seed, extent=recipe.extent))
