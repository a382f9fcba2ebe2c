"""Shared pieces of the uncertainty and planning tests (tiny sizes, built once per session).

The tests build everything from `configs/camera_planning.py:tiny`, so that equal training
configs share one compilation of the jitted training step (it is jitted module-wide with its
settings static), and the expensive objects are cached here for the whole session.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np

from configs import camera_planning
from mfsample.config_blocks import data_spec
from mfsample.groups import GROUPS
from mfsample.jobs import Budgets
from mfsample.model import init_model
from mfsample.planning import poses, runner
from mfsample.planning.pool import make_pool
from mfsample.samplers import SamplerSpec

BOUNDS = tuple((g, b) for g, b in zip(GROUPS, (1.0, 20.0, 2.0, 20.0, 0.5, 0.5), strict=True))


def tiny_config():
  return camera_planning.get_config("tiny")


@functools.cache
def tiny_run(workdir, strategies=("random", "farthest")):
  """A finished tiny planning run in `workdir` (default: two strategies that train no round
  model, so it is cheap); returns its results.json path."""
  config = tiny_config()
  config.strategies = tuple(strategies)
  config.figures.enabled = False
  runner.run_camera_planning(config, str(workdir))
  return workdir / "results.json"


def tiny_pool():
  """The synthetic pool of the tiny config (8 candidates, 2 test views, 24 x 24)."""
  return make_pool(data_spec(tiny_config().data))


def random_model(kind="lowrank", *, num=80, b_hat=0.05, seed=0, dtype=jnp.float32,
                 sh_degree=0, radius=0.5):
  """An untrained model: `num` Gaussians in [-radius, radius]^3 with B_hat entries of size
  ~`b_hat` (so that U > 0 without training)."""
  rng = np.random.default_rng(seed)
  points = rng.uniform(-radius, radius, (num, 3))
  spec = SamplerSpec(kind=kind, rank=2, groups=GROUPS if kind != "deterministic" else (),
                     bounds=BOUNDS)
  scales = {g: b_hat for g in GROUPS}
  model = init_model(jax.random.PRNGKey(seed), points, spec=spec, sh_degree=sh_degree,
                     init_scales=scales, init_opacity=0.6,
                     colors=rng.uniform(0.1, 0.9, (num, 3)))
  # init_model builds float32; cast the floating leaves (float64 needs conftest.float64).
  cast = lambda x: x.astype(dtype) if jnp.issubdtype(x.dtype, jnp.floating) else x
  return jax.tree.map(cast, model)


@functools.cache
def trained_one_view(kind="lowrank", view=0):
  """`Trained` of the tiny config's first round (one training view): the same training, and
  compilation, as the protocol's first round."""
  config = tiny_config()
  pool = tiny_pool()
  trainer = runner.Trainer(config, pool)
  sel = [runner.candidate_view(pool, view)]
  trained, _ = trainer.round_state("deterministic" if kind == "deterministic" else "stochastic",
                                   sel, 0, Budgets())
  return trained


def opposite_uv(uv):
  """(u, v) of the diametrically opposite point of the sphere."""
  return np.array([(uv[0] + 0.5) % 1.0, 1.0 - uv[1]])


def sphere_for(pool, v_range=(0.0, 1.0)):
  return pool.sphere.replace(v_range=v_range)


__all__ = ["poses", "random_model", "tiny_config", "tiny_pool", "trained_one_view"]
