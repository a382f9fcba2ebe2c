"""Static renderer settings: one frozen, hashable object, passed as a static argument."""

import dataclasses

from mfsample import settings_checks as sc

COMPOSITORS = ("jnp", "pallas")
SEARCHSORTED_METHODS = ("scan", "scan_unrolled", "sort", "compare_all")
PALLAS_WARPS = (0, 1, 2, 4, 8, 16, 32)  # 0: automatic


@dataclasses.dataclass(frozen=True)
class RenderSettings:
  """Everything about a render that is not a differentiable input.

  The rasterisation rule (as in INRIA 3DGS and gsplat): a Gaussian of opacity o contributes
  at a pixel p iff its Mahalanobis distance d(p) satisfies

    d(p) <= r(o) = min(radius_sigma, sqrt(2 ln(o / alpha_min))),

  which is exactly where its alpha o exp(-d^2 / 2) is >= alpha_min, up to the cap
  `radius_sigma`. The tiles it is listed in are those its footprint {d <= r(o)} touches
  (through the footprint's bounding box), so the image does not depend on `tile_size`.

  Attributes:
    tile_size: side of a square screen tile in pixels.
    alpha_max: per-Gaussian opacity clamp (3DGS: 0.99).
    alpha_min: contributions below this alpha are skipped (3DGS: 1/255).
    transmittance_min: a pixel stops accumulating once its transmittance would fall below
      this (3DGS: 1e-4); the Gaussian that would cross it is not blended.
    near_plane: Gaussians whose centre has camera depth z < near_plane are culled.
    eps2d: isotropic screen-space dilation added to every 2D covariance (pixels^2); a
      low-pass filter that also keeps the 2D covariance invertible.
    radius_sigma: cap of the footprint radius r(o) above, in standard deviations. At the
      default 3.33 = sqrt(2 ln 255) the alpha rule binds for every opacity <= 1, as in
      gsplat. 3.0 reproduces the images of the renderer before the alpha rule, which cut
      every Gaussian at 3 sigma.
    max_intersections: budget of (tile, Gaussian) pairs, counted after padding each tile's
      list to a multiple of `chunk_size`. Exceeding it sets `stats.overflow`; see
      `mfsample.renderer.budget.fit_budget` to grow it. Must be a multiple of
      chunk_size * chunks_per_step.
    chunk_size: Gaussians composited together in one dense block (per tile).
    chunks_per_step: chunks processed per step of the jnp compositor's loop; the backward
      pass keeps the activations of one step only, so this bounds memory. A speed knob:
      results agree to float rounding for any value.
    compositor: "jnp" (default; the pure jax.numpy compositor, `composite.py`) or "pallas"
      (a Pallas kernel, one program per tile, `composite_pallas.py`; meant for GPUs, run by
      the Pallas interpreter on a CPU). Its tile_size and chunk_size must be powers of two.
    searchsorted_method: `jnp.searchsorted`'s method in the tile intersection ("scan",
      "scan_unrolled", "sort", "compare_all"); a speed knob with identical results.
    skip_unused_steps: the jnp compositor skips the loop steps past the last chunk in use
      (a `lax.cond` per step). It saves the work of an over-provisioned budget, but on a
      GPU the host reads each step's predicate, a round trip per step; False runs every
      step without one. A speed knob: the results are identical.
    pallas_warps: Triton warps per program (tile) of the Pallas kernels: 0 (one warp per 32
      pixels of the tile, at most 8) or a power of two up to 32. With chunk_size it sets how
      many elements of each [tile pixels, chunk] block a thread holds. A speed knob (GPU
      only): the results are identical.
  """

  tile_size: int = 16
  alpha_max: float = 0.99
  alpha_min: float = 1.0 / 255.0
  transmittance_min: float = 1e-4
  near_plane: float = 0.2
  eps2d: float = 0.3
  radius_sigma: float = 3.33
  max_intersections: int = 1 << 16
  chunk_size: int = 32
  chunks_per_step: int = 16
  compositor: str = "jnp"
  searchsorted_method: str = "scan"
  skip_unused_steps: bool = True
  pallas_warps: int = 0

  def __post_init__(self):
    # Types and finiteness first: NaN passes every comparison below unnoticed (a NaN
    # radius_sigma renders nothing), and a float size fails deep inside jit.
    for name in ("tile_size", "chunk_size", "chunks_per_step"):
      sc.check_int(f"RenderSettings.{name}", getattr(self, name), minimum=1)
    sc.check_float("RenderSettings.alpha_max", self.alpha_max, above=0.0, maximum=1.0)
    sc.check_float("RenderSettings.alpha_min", self.alpha_min, minimum=0.0,
                   below=self.alpha_max)
    sc.check_float("RenderSettings.transmittance_min", self.transmittance_min, above=0.0,
                   below=1.0)
    sc.check_float("RenderSettings.near_plane", self.near_plane, above=0.0)
    sc.check_float("RenderSettings.eps2d", self.eps2d, minimum=0.0)
    sc.check_float("RenderSettings.radius_sigma", self.radius_sigma, above=0.0)
    step = self.chunk_size * self.chunks_per_step
    budget = sc.check_int("RenderSettings.max_intersections", self.max_intersections,
                          minimum=1)
    if budget < step or budget % step:
      raise sc.SettingsError("RenderSettings.max_intersections", budget,
                             f"a positive multiple of chunk_size * chunks_per_step ({step})")
    sc.check_choice("RenderSettings.compositor", self.compositor, COMPOSITORS)
    if self.compositor == "pallas" and not (_is_power_of_two(self.tile_size)
                                            and _is_power_of_two(self.chunk_size)):
      # The kernel works on [tile_size^2, chunk_size] blocks; GPU kernel languages (Triton)
      # need block sides that are powers of two.
      raise sc.SettingsError("RenderSettings.tile_size", (self.tile_size, self.chunk_size),
                             "powers of two (tile_size and chunk_size) for the pallas "
                             "compositor")
    sc.check_choice("RenderSettings.pallas_warps", self.pallas_warps, PALLAS_WARPS)
    sc.check_choice("RenderSettings.searchsorted_method", self.searchsorted_method,
                    SEARCHSORTED_METHODS)
    sc.check_bool("RenderSettings.skip_unused_steps", self.skip_unused_steps)

  @property
  def max_chunks(self):
    return self.max_intersections // self.chunk_size

  @classmethod
  def holding(cls, budget, **fields):
    """Settings with `fields` whose budget is the smallest whole number of compositing
    steps (chunk_size x chunks_per_step intersections) that holds `budget`."""
    step = (fields.get("chunk_size", cls.chunk_size)
            * fields.get("chunks_per_step", cls.chunks_per_step))
    return cls(max_intersections=max(1, -(-int(budget) // step)) * step, **fields)

  def holding_budget(self, budget):
    """These settings with the smallest valid budget that holds `budget`."""
    fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
              if f.name != "max_intersections"}
    return RenderSettings.holding(budget, **fields)

  def replace(self, **changes):
    return dataclasses.replace(self, **changes)


def _is_power_of_two(n):
  return n >= 1 and n & (n - 1) == 0
