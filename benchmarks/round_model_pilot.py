"""Time and U of a planning config's round model on the first views of a farthest-point run.

A sanity check for a new round recipe before any planning run: how long one round takes
(compilation included), how many Gaussians it ends with, and whether U is lowest at the
training views and rises with the angle to the nearest one (Spearman rho over the other
candidates). No PSNR: it says nothing about which strategy wins. It gave the pilot figures
of `configs/camera_planning_lego_rounds2000_authors.py`:

  PYTHONPATH=. python benchmarks/round_model_pilot.py \
      --config=configs/camera_planning_lego_rounds2000_authors.py \
      --results=results/camera_planning_lego_rounds2000/results.json --views=1,5 --z_seed=0

(the pilot scored with the Sobol seed 0, not the config's).
"""

import json
import time

from absl import app, flags
from ml_collections import config_flags

_CONFIG = config_flags.DEFINE_config_file("config", None, "Planning config.", lock_config=False)
_RESULTS = flags.DEFINE_string("results", None, "results.json holding a farthest-point run.")
_SEED = flags.DEFINE_integer("seed", 0, "Seed of the run, and of the round models.")
_VIEWS = flags.DEFINE_list("views", ["1", "5"], "Train on the run's first n views, each n.")
_Z_SEED = flags.DEFINE_integer("z_seed", -1, "Sobol scrambling seed of U (< 0: the config's).")
flags.mark_flags_as_required(["config", "results"])


def main(argv):
  del argv
  import jax.numpy as jnp
  import numpy as np
  import scipy.stats

  from mfsample import uncertainty as unc
  from mfsample.planning import poses, runner
  from mfsample.planning.pool import make_pool
  from mfsample.render import RenderSettings

  config = _CONFIG.value
  with open(_RESULTS.value) as f:
    run, = [r for r in json.load(f)["runs"]
            if r["strategy"] == "farthest" and r["seed"] == _SEED.value]
  pool = make_pool(config.data)
  trainer = runner.Trainer(config, pool)
  cameras = pool.candidates.cameras
  scored = poses.downscale_camera(cameras, int(config.strategy.score_downscale))
  for n in (int(v) for v in _VIEWS.value):
    indices = run["indices"][:n]
    t0 = time.perf_counter()
    trained = trainer.round_state(
        "stochastic", [runner.candidate_view(pool, i) for i in indices], _SEED.value)
    seconds = time.perf_counter() - t0
    z_seed = _Z_SEED.value if _Z_SEED.value >= 0 else int(config.strategy.ours.z_seed)
    z = unc.uncertainty_z(trained.model, int(config.strategy.ours.select_samples), z_seed)
    out, _ = unc.score_cameras(trained.model, scored, z,
                               settings=RenderSettings(max_intersections=1 << 12),
                               background=jnp.asarray(pool.background))
    u = np.asarray(out.values)
    angle = poses.angle_to_nearest(cameras, indices, pool.sphere.center)
    rest = np.setdiff1d(np.arange(len(u)), indices)
    rho = scipy.stats.spearmanr(u[rest], angle[rest])[0]
    print(f"{n} view(s): round {seconds:.0f} s, {int(np.asarray(trained.model.mask).sum())} "
          f"live Gaussians, U at the training views {', '.join(f'{x:.2f}' for x in u[indices])}, "
          f"median {np.median(u):.2f}, max {u.max():.2f}; rho(U, angle to the nearest "
          f"training view) {rho:+.2f}")


if __name__ == "__main__":
  app.run(main)
