"""Post-hoc uncertainty for a pretrained 3DGS model: fit B_hat with the mean frozen.

A model trained elsewhere (the 3DGS reference code, gsplat, nerfstudio: a `point_cloud.ply`)
becomes a stochastic field theta(z) = mean + B_hat z (paper Eq. 7) whose mean is the model
exactly as stored, by minimising the paper's loss (Eq. 9)

  L(B_hat) = (1 - w) L1 + w (1 - SSIM) of a sample theta(z), z ~ Sobol in [-1, 1]^k,
             - lambda ||B_hat||_1 on every `loss.volume_every`-th step,

over B_hat alone, on the model's training images. The mean's gradient is stopped
(`StepConfig.train_mean = False`): Adam's moments of the mean stay zero and so does its
update, bit for bit. The data term pulls B_hat in where moving a parameter changes the
rendered training views, the volume term pushes it out everywhere, so B_hat ends large where
the training views leave the model free: U (Eq. 10) and its per-pixel maps then follow
what the views did not constrain, as for a jointly trained field.

The loop is `mfsample.train.train` itself (render budgets, checkpoints and resume, logs),
without densification (the model keeps the file's Gaussians), with every SH band of the file
active from the first step, and a sample rendered at every step. Each step costs what a step
of joint training costs (one render and its backward pass); `config.train.num_steps` sets
how many.
"""

import dataclasses

from mfsample.data import ply
from mfsample.train.loop import TrainResult, make_setup, train

# lambda of the volume term when the config leaves it to the default (None). The authors'
# 1 / (number of views) is a weight for joint training with densification; with no
# densification and a few hundred steps it swamps the data term in Adam's normalisation, so
# that every B_hat entry grows at the same rate, seen or not (mfsample.planning.config). The
# planning rounds' 1e-4 is the value the post-hoc comparison of docs/your_data.md measured.
POSTHOC_VOLUME_WEIGHT = 1e-4


def posthoc_config(config, ply_path):
  """A copy of training `config` that fits B_hat to the mean of the 3DGS file `ply_path`.

  Starts from the file (`model.init_from = "ply"`, its SH degree), switches densification and
  opacity resets off, renders a sample at every step (`sampler.stochastic_until = None`: a
  step that renders the mean gives B_hat no data gradient). When `loss.volume_weight` is
  None, the volume term is weighed by `POSTHOC_VOLUME_WEIGHT`; when the steps without it at
  the end (`loss.volume_stop_before_end`) would be half the fit or more, they are cut to 5%
  of it (the authors: the last 100 of 2000). Everything else (sampler, loss, B_hat's
  learning rates and bounds, render budget, `train.num_steps`) is the config's.
  (`fit_spread` also freezes the mean and activates every SH band from the first step, in
  the step's static settings.)
  """
  if config.sampler.kind == "deterministic":
    raise ValueError("config.sampler.kind = 'deterministic' has no B_hat to fit; use "
                     "'lowrank' (the paper's), 'block' or 'diagonal'")
  degree = ply.sh_degree_of(ply.load_ply(ply_path))  # validates the file before anything runs
  cfg = config.copy_and_resolve_references()
  with cfg.unlocked():
    cfg.model.init_from = "ply"
    cfg.model.ply_path = str(ply_path)
    cfg.model.sh_degree = degree
    cfg.densify.start = 0
    cfg.densify.stop = 0  # no host events at all (`loop.host_events`)
    cfg.sampler.stochastic_until = None
    if cfg.loss.volume_weight is None:
      cfg.loss.volume_weight = POSTHOC_VOLUME_WEIGHT
    # The default's last 100 steps without the volume term are meant for runs of thousands
    # of steps; over half a short fit or more, they are cut to the authors' proportion.
    steps = int(cfg.train.num_steps)
    if 2 * int(cfg.loss.volume_stop_before_end) >= steps:
      cfg.loss.volume_stop_before_end = steps // 20
  return cfg


def fit_spread(config, views, ply_path, *, checkpoint_dir=None, key=None, settings=None,
               **train_kwargs) -> TrainResult:
  """Fits B_hat of a stochastic field whose mean is the 3DGS model `ply_path`.

  Args:
    config: a training config (`mfsample.train.default_config()`): its sampler, loss,
      B_hat learning rates and bounds, render budget and `train.num_steps` (the fit's
      length) apply; see `posthoc_config` for what is overridden.
    views: the model's training `Views`.
    ply_path: the model, a 3DGS `point_cloud.ply` (`mfsample.data.ply.load_ply`).
    checkpoint_dir: if set, resume from and write checkpoints there.
    key: optional PRNG key replacing `config.seed` (B_hat's start, z, view order).
    settings: optional `RenderSettings` to start from (a budget that sufficed before).
    **train_kwargs: passed to `mfsample.train.train` (`stop_at`, `num_views`, `max_traces`).

  Returns:
    `TrainResult`: `state.model` is the stochastic field, its mean the file's Gaussians
    exactly; `train_seconds` the cost of the fit.
  """
  cfg = posthoc_config(config, ply_path)
  setup = make_setup(cfg, views, key=key)
  # The mean frozen, and every SH band of the file active from the first step.
  step_config = dataclasses.replace(setup.step_config, train_mean=False, sh_degree_every=0)
  if settings is not None:
    step_config = dataclasses.replace(step_config, settings=settings)
  setup = setup._replace(step_config=step_config)
  return train(cfg, views, key=key, setup=setup, checkpoint_dir=checkpoint_dir, **train_kwargs)
