"""Host-side budget management: grow `max_intersections` instead of truncating.

`render` never drops work silently: when the padded intersection list exceeds
`settings.max_intersections`, `stats.overflow` is set and `stats.num_padded` says how much
was needed. These helpers turn that into new settings, growing the budget to the next power
of two, so a jitted caller recompiles at most log2(need / budget) times.
"""

from collections.abc import Callable

import numpy as np

from mfsample import arg_checks
from mfsample.renderer.settings import RenderSettings
from mfsample.renderer.tiles import TileStats


class BudgetExceededError(RuntimeError):
  """Raised when a render overflowed and growing the budget is not allowed."""


def required_budget(settings: RenderSettings, stats) -> int:
  """The smallest valid power-of-two budget that holds `stats` (max over any batch axes)."""
  need = int(np.max(np.asarray(stats.num_padded)))
  return settings.holding_budget(1 << max(need - 1, 0).bit_length()).max_intersections


def fit_budget(settings: RenderSettings, stats: TileStats, *,
               allow_shrink: bool = False) -> RenderSettings:
  """Settings whose budget holds the render that produced `stats`.

  Grows to the next power of two >= the padded intersection count (never shrinks unless
  `allow_shrink`, so a training loop does not oscillate between compilations).

  Args:
    settings: the settings the render ran with.
    stats: its `TileStats` (any leading batch axes: the largest count decides).
    allow_shrink: also lower the budget when the render needed less.

  Returns:
    `settings`, or a copy with the budget that holds the render.
  """
  budget = required_budget(settings, stats)
  if not allow_shrink:
    budget = max(budget, settings.max_intersections)
  if budget == settings.max_intersections:
    return settings
  return settings.replace(max_intersections=budget)


def render_with_budget(render_fn: Callable, settings: RenderSettings, *args,
                       max_budget: int = 1 << 26,
                       stats_of: Callable = lambda out: out.stats, what: str = "render",
                       **kwargs) -> tuple[object, RenderSettings]:
  """Calls `render_fn(*args, settings=settings, **kwargs)` until nothing overflows.

  Args:
    render_fn: a (possibly jitted, possibly vmapped) function of `settings` whose output
      carries the overflow statistics of its renders.
    settings: the starting settings.
    max_budget: refuse (BudgetExceededError) to grow beyond this many intersections.
    stats_of: output -> an object with `overflow` and `num_padded` (any batch shape);
      default: the output's `.stats` (`RenderOutput`, `TileStats`).
    what: names the work in the error message.

  Returns:
    (output, settings) with the settings that sufficed, to reuse on the next call.
  """
  arg_checks.check_int("max_budget", max_budget, minimum=1)
  while True:
    out = render_fn(*args, settings=settings, **kwargs)
    stats = stats_of(out)
    if not bool(np.any(np.asarray(stats.overflow))):
      return out, settings
    grown = fit_budget(settings, stats)
    if grown.max_intersections > max_budget:
      raise BudgetExceededError(
          f"{what} needs {int(np.max(np.asarray(stats.num_padded)))} intersections, "
          f"more than max_budget={max_budget}")
    settings = grown
