"""Post-hoc uncertainty for a pretrained 3DGS model: fit B_hat with the mean frozen.

A model trained elsewhere (the 3DGS reference code, gsplat, nerfstudio: a `point_cloud.ply`)
becomes a stochastic field theta(z) = mean + B_hat z (paper Eq. 7) whose mean is the model
exactly as stored, by minimising the paper's loss (Eq. 9)

  L(B_hat) = (1 - w) L1 + w (1 - SSIM) of a sample theta(z), z ~ Sobol in [-1, 1]^k,
             - lambda ||B_hat||_1 on every `loss.volume_every`-th step,

over B_hat alone, on the model's training images. The mean's gradient is stopped
(`TrainSettings.train_mean = False`): Adam's moments of the mean stay zero and so does its
update, bit for bit. The data term pulls B_hat in where moving a parameter changes the
rendered training views, the volume term pushes it out everywhere, so B_hat ends large where
the training views leave the model free: U (Eq. 10) and its per-pixel maps then follow
what the views did not constrain, as for a jointly trained field.

The loop is `mfsample.train.fit` itself (render budgets, checkpoints and resume, history),
without densification (the model keeps the file's Gaussians), with every SH band of the file
active from the first step, and a sample rendered at every step (`posthoc_settings`). Each
step costs what a step of joint training costs (one render and its backward pass);
`TrainSettings.num_steps` sets how many.
"""

import jax

from mfsample import arg_checks
from mfsample.data.views import Views
from mfsample.model import Model
from mfsample.train.loop import TrainResult, fit, run_training
from mfsample.train.settings import TrainSettings

# lambda of the volume term when the settings leave it to the default (None). The authors'
# 1 / (number of views) is a weight for joint training with densification; with no
# densification and a few hundred steps it swamps the data term in Adam's normalisation, so
# that every B_hat entry grows at the same rate, seen or not (mfsample.planning.config). The
# planning rounds' 1e-4 is the value the post-hoc comparison of docs/your_data.md measured.
POSTHOC_VOLUME_WEIGHT = 1e-4


def posthoc_settings(settings: TrainSettings) -> TrainSettings:
  """`settings` for fitting B_hat to a model's frozen mean.

  The mean frozen (`train_mean = False`), every SH band active from the first step
  (`sh_degree_every = 0`), no densification nor opacity reset (the model keeps its
  Gaussians), a sample rendered at every step (`stochastic_until = None`: a step that
  renders the mean gives B_hat no data gradient). When `loss.volume_weight` is None, the
  volume term is weighed by `POSTHOC_VOLUME_WEIGHT`; when the steps without it at the end
  (`loss.volume_stop_before_end`) would be half the fit or more, they are cut to 5% of it
  (the authors: the last 100 of 2000). Everything else (loss, B_hat's learning rates, the
  render budget, `num_steps`: the fit's length) is the settings'.
  """
  loss = settings.loss
  if loss.volume_weight is None:
    loss = loss.replace(volume_weight=POSTHOC_VOLUME_WEIGHT)
  # The default's last 100 steps without the volume term are meant for runs of thousands of
  # steps; over half a short fit or more, they are cut to the authors' proportion.
  if 2 * loss.volume_stop_before_end >= settings.num_steps:
    loss = loss.replace(volume_stop_before_end=settings.num_steps // 20)
  return settings.replace(train_mean=False, sh_degree_every=0, stochastic_until=None,
                          densify=settings.densify.replace(start=0, stop=0), loss=loss)


def _check_stochastic(model):
  if not isinstance(model, Model):
    raise ValueError(f"model must be a mfsample.Model, got {type(model).__name__}")
  if not model.spec.stochastic:
    raise ValueError(f"model's sampler ({model.spec.kind}, groups {model.spec.groups}) has no "
                     "B_hat to fit: give it a stochastic spec ('lowrank', the paper's, "
                     "'block' or 'diagonal', with groups)")


def run_b_hat_fit(model: Model, views: Views, settings: TrainSettings, *, seed,
                  **kwargs) -> TrainResult:
  """`fit_b_hat` with `run_training`'s record (checkpoints, resume, budget, seconds)."""
  _check_stochastic(model)
  return run_training(model, views, posthoc_settings(settings), seed=seed, **kwargs)


def fit_b_hat(model: Model, views: Views, settings: TrainSettings = TrainSettings(), *,
              key: jax.Array, **kwargs) -> tuple[Model, list]:
  """Fits B_hat of a stochastic field whose mean is a pretrained model, frozen.

  Args:
    model: a stochastic `Model` whose mean is the trained 3DGS model
      (`mfsample.model.model_from_mean` of `mfsample.data.load_ply`), its B_hat small and
      fresh; every SH band it holds is used.
    views: the model's training `Views`.
    settings: `TrainSettings`, overridden as `posthoc_settings` says; `num_steps` is the
      fit's length (each step costs one training step).
    key: a JAX PRNG key (z, view order).
    **kwargs: `run_training`'s (`extent`, `num_views`, `checkpoint_dir`, ...).

  Returns:
    (the field: its mean the given model's, bit for bit; the history).
  """
  _check_stochastic(model)
  arg_checks.check_key(key)
  return fit(model, views, posthoc_settings(settings), key=key, **kwargs)
