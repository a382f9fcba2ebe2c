"""Typed, frozen settings of training: what `fit` takes, every field defaulted.

`TrainSettings` holds everything the paper's training (Eq. 9, the volume term, 3DGS
densification) needs beyond the model and the views, with the defaults of the training job
(`configs/train.py`); it nests `LossSettings`, `OptimSettings`, `DensifySettings` and the
renderer's `RenderSettings`. `InitSettings` says how a job builds the model a run starts
from. Each object checks its fields on construction (`mfsample.settings_checks`): the
config validators of the jobs build them, so a rule is stated once.

Numbers without a comment on their origin follow 3DGS (Kerbl et al. 2023); those of B_hat
follow the authors' public code, where the paper is silent.
"""

import dataclasses

from mfsample import settings_checks as sc
from mfsample.groups import GROUP_ORDER
from mfsample.renderer.settings import RenderSettings

NEVER = 2**31 - 1  # a step no run reaches


@dataclasses.dataclass(frozen=True)
class LossSettings:
  """Eq. 9: (1 - w) L1 + w (1 - SSIM) of a sample, minus lambda ||B_hat||_1.

  Attributes:
    ssim_weight: w of the D-SSIM term (3DGS: 0.2).
    volume_weight: lambda of the volume term on the plain sum of `|B_hat|`; None: 1 / (number
      of training views), as in the authors' code (the paper's text says 1).
    volume_every: the volume term is applied on every `volume_every`-th step only (paper).
    volume_stop_before_end: no volume term in the run's last steps (authors: 100).
  """

  ssim_weight: float = 0.2
  volume_weight: float | None = None
  volume_every: int = 10
  volume_stop_before_end: int = 100

  def __post_init__(self):
    sc.check_float("LossSettings.ssim_weight", self.ssim_weight, minimum=0.0, maximum=1.0)
    sc.check_float("LossSettings.volume_weight", self.volume_weight, minimum=0.0,
                   optional=True)
    sc.check_int("LossSettings.volume_every", self.volume_every, minimum=1)
    sc.check_int("LossSettings.volume_stop_before_end", self.volume_stop_before_end, minimum=0)

  def replace(self, **changes):
    return dataclasses.replace(self, **changes)


# Adam's learning rates of the mean's groups other than the centres, and of B_hat's entries
# (centres: times the extent, constant). SH rest: 3DGS's feature rate / 20. The relightable
# field's transfer matrices (`mfsample.lighting`): 4x the authors' rates of T's rows (their
# 20:1 ratio kept), B_hat's 0.1x T's (the authors' ratio); docs/lighting.md.
MEAN_LR = {"log_scales": 5e-3, "quats": 1e-3, "opacity_logits": 0.05, "sh_dc": 2.5e-3,
           "sh_rest": 1.25e-4, "transfer_dc": 5e-3, "transfer_rest": 2.5e-4}
B_HAT_LR = {"means": 1.6e-5, "log_scales": 5e-4, "quats": 1e-4, "opacity_logits": 5e-3,
            "sh_dc": 2.5e-3, "sh_rest": 1.25e-4, "transfer_dc": 5e-4, "transfer_rest": 2.5e-5}


@dataclasses.dataclass(frozen=True)
class OptimSettings:
  """Adam's per-group learning rates (3DGS; B_hat: the authors' code).

  Attributes:
    position_lr_init: centres' rate at step 0, times the scene extent; decays exponentially
      (log-linearly) ...
    position_lr_final: ... to this (times extent) ...
    position_lr_max_steps: ... over this many steps (None: the whole run).
    mean_lr: {group: rate} of the mean's other groups (a model's groups must all be there).
    b_hat_lr: {group: rate} of B_hat's raw entries; the centres' times the extent, constant.
  Mappings are held as sorted (group, rate) pairs (hashable); a dict is accepted.
  """

  position_lr_init: float = 1.6e-4
  position_lr_final: float = 1.6e-6
  position_lr_max_steps: int | None = None
  mean_lr: tuple = tuple(MEAN_LR.items())
  b_hat_lr: tuple = tuple(B_HAT_LR.items())

  def __post_init__(self):
    sc.check_float("OptimSettings.position_lr_init", self.position_lr_init, above=0.0)
    sc.check_float("OptimSettings.position_lr_final", self.position_lr_final, above=0.0)
    sc.check_int("OptimSettings.position_lr_max_steps", self.position_lr_max_steps, minimum=1,
                 optional=True)
    sc.set_field(self, "mean_lr", sc.check_table("OptimSettings.mean_lr", self.mean_lr,
                                                 GROUP_ORDER[1:], minimum=0.0))
    sc.set_field(self, "b_hat_lr", sc.check_table("OptimSettings.b_hat_lr", self.b_hat_lr,
                                                  GROUP_ORDER, minimum=0.0))

  def replace(self, **changes):
    return dataclasses.replace(self, **changes)


@dataclasses.dataclass(frozen=True)
class DensifySettings:
  """3DGS adaptive density control (Kerbl et al. 2023, Sec. 5.2), on the host.

  Attributes:
    start: first densification after this step ...
    stop: ... and none from this step on ...
    every: ... every this many steps.
    grad_threshold: mean NDC gradient norm of a Gaussian that triggers clone / split.
    percent_dense: clone if the largest scale <= this x extent, else split.
    min_opacity: prune below this opacity (3DGS; the authors' code: 0.01).
    opacity_reset_every: opacity reset period while densifying.
    prune_big_after: from this step on, also prune very large Gaussians: ...
    max_world_size: ... larger than this x extent, ...
    max_screen_size: ... or (if > 0) wider than this many pixels on screen. 3DGS passes 20 px
      but resets the radii it compares right before, so in effect it never prunes by screen
      size; 0 is off.
    max_gaussians: densification never exceeds this many live Gaussians.
  """

  start: int = 500
  stop: int = 15_000
  every: int = 100
  grad_threshold: float = 2e-4
  percent_dense: float = 0.01
  min_opacity: float = 0.005
  opacity_reset_every: int = 3000
  prune_big_after: int = 3000
  max_world_size: float = 0.1
  max_screen_size: float = 0.0
  max_gaussians: int = 40_000

  def __post_init__(self):
    for name in ("start", "stop", "prune_big_after"):
      sc.check_int(f"DensifySettings.{name}", getattr(self, name), minimum=0)
    for name in ("every", "opacity_reset_every", "max_gaussians"):
      sc.check_int(f"DensifySettings.{name}", getattr(self, name), minimum=1)
    sc.check_float("DensifySettings.grad_threshold", self.grad_threshold, minimum=0.0)
    sc.check_float("DensifySettings.percent_dense", self.percent_dense, minimum=0.0)
    sc.check_float("DensifySettings.min_opacity", self.min_opacity, minimum=0.0, below=1.0)
    sc.check_float("DensifySettings.max_world_size", self.max_world_size, above=0.0)
    sc.check_float("DensifySettings.max_screen_size", self.max_screen_size, minimum=0.0)

  @classmethod
  def off(cls, **fields):
    """Settings that never densify, prune or reset opacities (fixed shapes: one compilation
    of the step for the whole run)."""
    return cls(**{"start": NEVER, "stop": NEVER, "opacity_reset_every": NEVER,
                  "prune_big_after": NEVER, **fields})

  def active_within(self, num_steps):
    """Whether a run of `num_steps` steps densifies (and so changes shape)."""
    return self.start < num_steps

  def replace(self, **changes):
    return dataclasses.replace(self, **changes)


@dataclasses.dataclass(frozen=True)
class TrainSettings:
  """Everything `mfsample.train.fit` needs beyond the model and the views.

  Attributes:
    num_steps: optimisation steps (3DGS: 30k; the training job: 7000).
    batch_size: B views per step (data-parallel over the devices; docs/scaling.md). The
      schedules count steps, so B > 1 sees B times as many views in `num_steps`.
    num_samples: M, samples theta(z) rendered per step (paper: 1).
    stochastic_until: steps that render samples; later steps render the mean while the
      volume term goes on. None: every step (the paper's text; the authors' code: 3000).
    z_seed: scrambling seed of the steps' Sobol z (low-rank sampler; authors' code: 6174).
    b_hat_init_scale: fresh raw B_hat entries (densification's) are this x U[0, 1] ...
    b_hat_init_extent_groups: ... times the extent for these groups.
    extent: scene extent in world units (scales the centres' rates and bound, and
      densification); None: 3DGS's, from the training cameras.
    background: RGB behind the Gaussians, as in the training images.
    sh_degree_every: the active SH degree rises by one this often (3DGS: 1000); 0: every band
      from the first step (a model trained elsewhere).
    train_mean: False freezes the mean: only B_hat is fitted (post-hoc uncertainty of a
      pretrained model, `mfsample.train.fit_b_hat`).
    max_budget: the render budget is grown on overflow up to this many intersections (an
      error beyond, never a truncated image).
    log_every: a history entry every this many steps (and at the last).
    loss, optim, densify: `LossSettings`, `OptimSettings`, `DensifySettings`.
    render: `RenderSettings` of the training renders (`max_intersections`: the starting
      budget).
  """

  num_steps: int = 7_000
  batch_size: int = 1
  num_samples: int = 1
  stochastic_until: int | None = None
  z_seed: int = 6174
  b_hat_init_scale: float = 1e-3
  b_hat_init_extent_groups: tuple = ("means", "log_scales")
  extent: float | None = None
  background: tuple = (1.0, 1.0, 1.0)
  sh_degree_every: int = 1000
  train_mean: bool = True
  max_budget: int = 1 << 24
  log_every: int = 100
  loss: LossSettings = LossSettings()
  optim: OptimSettings = OptimSettings()
  densify: DensifySettings = DensifySettings()
  render: RenderSettings = RenderSettings()

  def __post_init__(self):
    sc.check_int("TrainSettings.num_steps", self.num_steps, minimum=1)
    sc.check_int("TrainSettings.batch_size", self.batch_size, minimum=1)
    sc.check_int("TrainSettings.num_samples", self.num_samples, minimum=1)
    sc.check_int("TrainSettings.stochastic_until", self.stochastic_until, minimum=0,
                 optional=True)
    sc.check_int("TrainSettings.z_seed", self.z_seed, minimum=0, maximum=2**32 - 1)
    sc.check_float("TrainSettings.b_hat_init_scale", self.b_hat_init_scale, minimum=0.0)
    sc.set_field(self, "b_hat_init_extent_groups", sc.check_names(
        "TrainSettings.b_hat_init_extent_groups", self.b_hat_init_extent_groups, GROUP_ORDER))
    sc.check_float("TrainSettings.extent", self.extent, above=0.0, optional=True)
    sc.set_field(self, "background", sc.check_floats("TrainSettings.background",
                                                     self.background, 3, minimum=0.0,
                                                     maximum=1.0))
    sc.check_int("TrainSettings.sh_degree_every", self.sh_degree_every, minimum=0)
    sc.check_bool("TrainSettings.train_mean", self.train_mean)
    sc.check_int("TrainSettings.max_budget", self.max_budget, minimum=1)
    sc.check_int("TrainSettings.log_every", self.log_every, minimum=1)
    for name, cls in (("loss", LossSettings), ("optim", OptimSettings),
                      ("densify", DensifySettings), ("render", RenderSettings)):
      if not isinstance(getattr(self, name), cls):
        raise sc.SettingsError(f"TrainSettings.{name}", getattr(self, name),
                               f"a {cls.__name__}")
    if self.render.max_intersections > self.max_budget:
      raise sc.SettingsError("TrainSettings.max_budget", self.max_budget,
                             f"an integer >= render.max_intersections = "
                             f"{self.render.max_intersections}")

  def b_hat_init_scales(self, extent, groups=GROUP_ORDER):
    """{group: scale of fresh raw B_hat entries}: `b_hat_init_scale`, times `extent` for the
    groups of `b_hat_init_extent_groups`."""
    return {g: self.b_hat_init_scale * (extent if g in self.b_hat_init_extent_groups else 1.0)
            for g in groups}

  def replace(self, **changes):
    return dataclasses.replace(self, **changes)


INIT_FROM = ("random", "points", "ply")


@dataclasses.dataclass(frozen=True)
class InitSettings:
  """The model a training job starts from (`mfsample.train.initial`).

  Attributes:
    sh_degree: the model's maximum SH degree (0..3); 0 stores no SH-rest arrays.
    init_points: "random": this many points uniform in the scene box (3DGS without SfM).
    init_opacity: initial opacity of every Gaussian.
    init_from: "random", "points" (the dataset's SfM points and colours) or "ply" (the
      Gaussians of a trained 3DGS model at `ply_path`; `sh_degree` must match it).
    ply_path: "ply": a 3DGS point_cloud.ply (relative: to the working directory).
  """

  sh_degree: int = 3
  init_points: int = 5_000
  init_opacity: float = 0.1
  init_from: str = "random"
  ply_path: str = ""

  def __post_init__(self):
    sc.check_int("InitSettings.sh_degree", self.sh_degree, minimum=0, maximum=3)
    sc.check_int("InitSettings.init_points", self.init_points, minimum=1)
    sc.check_float("InitSettings.init_opacity", self.init_opacity, above=0.0, below=1.0)
    sc.check_choice("InitSettings.init_from", self.init_from, INIT_FROM)
    sc.check_str("InitSettings.ply_path", self.ply_path)
    if self.init_from == "ply" and not self.ply_path:
      raise sc.SettingsError("InitSettings.ply_path", self.ply_path,
                             "the 3DGS point_cloud.ply to start from (init_from = 'ply')")

  def replace(self, **changes):
    return dataclasses.replace(self, **changes)

