"""Uncertainty in .ply files: splat files in the reference layout (62-float records, geometry
untouched), the uncertainty per Gaussian beside them, and a render of the coloured file that
lights up where an unseen view's U map does."""


import jax.numpy as jnp
import numpy as np
import pytest
from planning_testlib import tiny_pool, trained_one_view
from ply_testlib import fixed_records

from mfsample import render
from mfsample import view_uncertainty as unc
from mfsample.data.ply import load_ply, read_vertex_table
from mfsample.gaussian_uncertainty import gaussian_uncertainty
from mfsample.metrics import spearman
from mfsample.model import activate
from mfsample.samplers import sample_z
from mfsample.your_data.uncertainty_ply import write_uncertainty_plys


@pytest.fixture(scope="module")
def written(tmp_path_factory):
  """A field trained on one view of the tiny pool; shares over the other candidates but the
  one farthest from the training view (the unseen target), written as .ply files."""
  trained = trained_one_view()
  pool = tiny_pool()
  model = trained.model
  centers = np.asarray(pool.candidates.cameras.center)
  target = int(np.argmax(np.linalg.norm(centers - centers[0], axis=1)))
  others = [i for i in range(1, len(centers)) if i != target]
  z = sample_z(model, 8)
  bg = jnp.asarray(pool.background, jnp.float32)
  per = gaussian_uncertainty(model, pool.candidates.cameras[np.asarray(others)], z,
                             settings=trained.settings, background=bg)
  directory = tmp_path_factory.mktemp("uply")
  coloured, own, extras = write_uncertainty_plys(directory, model, per)
  return (model, per, coloured, own, extras, pool.candidates.cameras[target], z,
          trained.settings, bg)


@pytest.mark.slow
def test_files_keep_the_geometry_and_carry_the_uncertainty(written):
  model, per, coloured, own, extras, *_ = written
  live = np.asarray(model.mask)
  mean = {g: np.asarray(v)[live] for g, v in model.params.mean.items()}
  for path in (coloured, own):
    records = fixed_records(path)  # as the reference SIBR viewer reads them
    assert records.shape == (int(live.sum()), 62)
    np.testing.assert_array_equal(records[:, 0:3], mean["means"])
    np.testing.assert_array_equal(records[:, 54], mean["opacity_logits"])
    np.testing.assert_array_equal(records[:, 55:58], mean["log_scales"])
    np.testing.assert_array_equal(records[:, 58:62], mean["quats"])
    raw = load_ply(path)  # and as readers by property name do
    for group in ("means", "log_scales", "quats", "opacity_logits"):
      np.testing.assert_array_equal(raw[group], mean[group])
  records = fixed_records(own)
  np.testing.assert_array_equal(records[:, 6:9], mean["sh_dc"])
  rest = records[:, 9:54].reshape(-1, 3, 15)
  sh_rest = mean.get("sh_rest", np.zeros((len(records), 0, 3), np.float32))
  k = sh_rest.shape[1]
  np.testing.assert_array_equal(rest[:, :, :k], np.transpose(sh_rest, (0, 2, 1)))
  assert not np.any(rest[:, :, k:]) and not np.any(fixed_records(coloured)[:, 9:54])
  table = read_vertex_table(extras)  # the uncertainty, row for row
  assert table.dtype.names == ("x", "y", "z", "u_share", "position_std", "colour_std")
  np.testing.assert_array_equal(np.stack([table[a] for a in "xyz"], -1), mean["means"])
  np.testing.assert_array_equal(table["u_share"], per.share[live])
  np.testing.assert_array_equal(table["position_std"], per.position_std[live])
  np.testing.assert_array_equal(table["colour_std"], per.colour_std[live])


@pytest.mark.slow
def test_the_coloured_file_lights_up_where_an_unseen_view_is_uncertain(written):
  """Rendered from a view none of the shares came from, the brightest Gaussians of the
  coloured file sit where that view's U map is high."""
  model, per, coloured, _, _, camera, z, settings, bg = written
  raw = load_ply(coloured)
  gaussians = activate({g: jnp.asarray(v) for g, v in raw.items()}, None,
                       jnp.asarray(3, jnp.int32))
  out = render(gaussians, camera, settings=settings, background=jnp.zeros(3))
  assert not np.any(out.stats.overflow)
  brightness = np.asarray(out.rgb).sum(-1)
  u_map = np.asarray(unc.uncertainty(model, camera, z, settings=settings,
                                     background=bg).pixel_map)
  covered = np.asarray(out.alpha) > 0.5
  rho = spearman(brightness[covered], u_map[covered])
  assert rho is not None and rho > 0.4, rho
  # The top tenth of the Gaussians by share land on pixels of high U in the unseen view.
  live = np.asarray(model.mask)
  share = per.share[live]
  uv, depth = camera.project(jnp.asarray(raw["means"]))
  uv, depth = np.asarray(uv), np.asarray(depth)
  col, row = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
  inside = (depth > 0) & (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height)
  top = inside & (share >= np.quantile(share, 0.9))
  bottom = inside & (share <= np.quantile(share, 0.5))
  assert top.sum() >= 3 and bottom.sum() >= 3
  at = lambda m: u_map[row[m], col[m]]
  assert np.median(at(top)) > 2.0 * np.median(at(bottom)), (np.median(at(top)),
                                                            np.median(at(bottom)))



def test_share_colours_run_from_dark_to_light_up_to_the_live_percentile():
  """magma from 0 to the 99th percentile of the live Gaussians' shares: a larger share is a
  lighter colour, a share above the top (or a dead Gaussian's) saturates."""
  from mfsample.your_data.uncertainty_ply import share_colours

  share = np.array([0.0, 1.0, 2.0, 3.0, 100.0])
  live = np.array([True, True, True, True, False])
  colours = share_colours(share, live)
  assert colours.shape == (5, 3) and np.all((colours >= 0) & (colours <= 1))
  brightness = colours.sum(-1)
  assert np.all(np.diff(brightness[:4]) > 0)
  np.testing.assert_allclose(colours[4], share_colours(share, live, percentile=100.0)[3])
