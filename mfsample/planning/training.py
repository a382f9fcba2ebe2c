"""A thin adapter over `mfsample.train` for the planning protocol.

The protocol trains a fresh model after every added view. Calling
`mfsample.train.train` on 1, 2, ..., 9 views would compile the jitted training step nine
times per model kind, because the step takes the stacked training images as an argument
and their leading axis grows. `train_on_views` instead pads the images to a fixed number
of slots (`pad_to`) and draws the step's view only among the real ones, with the training
code's own loop (`train(..., num_views=n)`), so one compilation serves every round:
set-up, initial state, the jitted step and budget growth on overflow are the training
module's.

For the same reason the config must fix what would otherwise change with the views and
sits in the step's static settings: `data.extent` and `loss.volume_weight` (the authors
use 1 / number of views; the planning configs state the constant they use instead).
`train_on_views` can also continue from a previous state on a larger view set, for the
paper's reading of the protocol (one training run, a camera added every so many steps).
A model that densifies changes shape as it trains, so padding saves nothing: rounds and
final models with densification (`densify.start < train.num_steps`) go through
`train_densified`, which is `mfsample.train.train` itself (one compilation per view count
and capacity), with the authors' volume weight 1 / number of views allowed.
"""

import dataclasses
from typing import NamedTuple

import numpy as np

from mfsample.train import init_state, make_setup, train


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


def _with_seed(config, seed):
  config = config.copy_and_resolve_references()
  with config.unlocked():
    config.seed = int(seed)
    config.train.progress = False
  return config


def _box(bounds):
  low, high = bounds
  return np.broadcast_to(np.asarray(low, np.float64), (3,)), np.broadcast_to(
      np.asarray(high, np.float64), (3,))


def densifies(config):
  """Whether a training config densifies (and so changes shape) within its run."""
  return config.densify.start < config.train.num_steps


def train_on_views(config, views, *, seed, bounds, pad_to, settings=None, state=None,
                   stop_at=None) -> Trained:
  """Trains a model on `views` (no densification): fresh, or continuing from `state`.

  The schedules (learning-rate decay, the volume term's last steps) follow
  `config.train.num_steps`; `stop_at` ends the call earlier, so that training can continue
  later from the returned state on more views (the paper's text: one run, a camera added
  every so many steps).

  Args:
    config: a training config (`mfsample.train.default_config()` layout) with `data.extent` and
      `loss.volume_weight` set (see the module docstring).
    views: the training `Views` (1 <= len(views) <= pad_to).
    seed: seeds the initial point cloud, B_hat signs, the z sequence and the view order.
    bounds: (low, high) box of the random initial point cloud.
    pad_to: number of image slots of the jitted step (the protocol's maximum views).
    settings: optional `RenderSettings` to start from (a budget that sufficed before).
    state: optional `TrainState` to continue from (default: a fresh initial state).
    stop_at: stop when this many steps are done in total (default: config.train.num_steps).

  Returns:
    `Trained`.
  """
  config = _with_seed(config, seed)
  n = len(views)
  if not 1 <= n <= pad_to:
    raise ValueError(f"need 1 <= len(views) <= pad_to, got {n} views and pad_to={pad_to}")
  if config.data.get("extent") is None or config.loss.volume_weight is None:
    raise ValueError("train_on_views needs config.data.extent and config.loss.volume_weight "
                     "set: otherwise the jitted step recompiles for every view count")
  if densifies(config):
    raise ValueError("train_on_views trains padded, fixed-shape models without "
                     "densification: set densify.start >= train.num_steps, or use "
                     "train_densified")
  setup = _setup(config, views, settings)
  if state is None:
    state = init_state(config, setup, _box(bounds))
  slots = np.minimum(np.arange(pad_to), n - 1)  # padding repeats the last view, never drawn
  result = train(config, views.subset(slots), setup=setup, state=state, stop_at=stop_at,
                 num_views=n)
  return _trained(result, with_state=True)


def _setup(config, views, settings):
  setup = make_setup(config, views)
  if settings is not None:
    setup = setup._replace(step_config=dataclasses.replace(setup.step_config,
                                                           settings=settings))
  return setup


def _trained(result, with_state=False) -> Trained:
  loss = result.history[-1]["data_loss"] if result.history else float("nan")
  return Trained(result.state.model, result.setup.step_config.settings, result.seconds, loss,
                 result.state if with_state else None)


def train_densified(config, views, *, seed, bounds, settings=None) -> Trained:
  """Trains a model on `views` with `mfsample.train.train` as it is, densification included
  (the final models' path; the rounds' when their config densifies)."""
  config = _with_seed(config, seed)
  result = train(config, views, setup=_setup(config, views, settings), bounds=_box(bounds))
  return _trained(result)
