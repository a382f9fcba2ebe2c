"""`render` for training: the same stages, plus what densification needs.

3DGS densifies where the loss gradient w.r.t. the *screen-space* centres is large (Kerbl
et al. 2023, Sec. 5.2). `mfsample.render` does not expose the 2D centres, so this module
chains the renderer's stages itself and adds a zero offset to the projected centres: the
gradient w.r.t. that offset is the gradient w.r.t. the 2D centres. It also returns the
screen radii and visibility (for the screen-size pruning rule). The image is the same as
`mfsample.render`'s, bit for bit (tested), so training and evaluation see one renderer.
"""

from typing import NamedTuple

import chex
import jax.numpy as jnp

from mfsample.gaussians import Gaussians
from mfsample.render import sh as sh_lib
from mfsample.render.composite import composite
from mfsample.render.projection import project_gaussians, view_directions
from mfsample.render.settings import RenderSettings
from mfsample.render.tiles import TileStats, intersect_tiles


class TrainRender(NamedTuple):
  """What `render_for_training` returns.

  Attributes:
    rgb: [H, W, 3] colour over the background.
    alpha: [H, W] accumulated opacity.
    radii: [N] screen radius in pixels (0 when culled; no gradient).
    visible: [N] bool, projected on screen and live.
    stats: `TileStats` (overflow is checked by the training loop).
  """

  rgb: chex.Array
  alpha: chex.Array
  radii: chex.Array
  visible: chex.Array
  stats: TileStats


def render_for_training(gaussians: Gaussians, camera, offset2d, *, background,
                        settings: RenderSettings) -> TrainRender:
  """Renders like `mfsample.render`, with the 2D centres shifted by `offset2d`.

  Args:
    gaussians: unbatched `Gaussians` (N >= 1).
    camera: unbatched `Camera`.
    offset2d: [N, 2] pixel offset added to the projected centres; pass zeros and
      differentiate w.r.t. it to get dL/d(means2d).
    background: [3] colour.
    settings: `RenderSettings` (static).

  Returns:
    `TrainRender`.
  """
  gaussians.validate()
  dtype = gaussians.means.dtype
  proj = project_gaussians(gaussians.means, gaussians.scales, gaussians.quats,
                           gaussians.opacities, gaussians.mask, camera, settings)
  means2d = proj.means2d + jnp.where(proj.valid[:, None], offset2d.astype(dtype), 0.0)
  colors = sh_lib.sh_to_color(gaussians.sh, view_directions(gaussians.means, camera))
  background = jnp.asarray(background, dtype)
  layout = intersect_tiles(proj, camera.width, camera.height, settings)
  blend_in = jnp.concatenate([colors, proj.depths[:, None]], axis=-1)
  opacities = jnp.where(proj.valid, gaussians.opacities, 0.0)
  blended, alpha = composite(layout, means2d, proj.conics, opacities, blend_in,
                             camera.width, camera.height, settings)
  rgb = blended[..., :3] + (1.0 - alpha)[..., None] * background
  return TrainRender(rgb=rgb, alpha=alpha, radii=proj.radii, visible=proj.valid,
                     stats=layout.stats)
