"""Time to score one candidate view: ours (M forward renders) against FisherRF (backward passes).

Ours scores a candidate with M forward renders of sampled models (Eq. 10); FisherRF needs
the diagonal Fisher information of the candidate's render, i.e. backward passes (here K
Rademacher probes, one vector-Jacobian product each). Both run on the same model, the same
candidate cameras and the same render settings, in one process. Every scorer is compiled
first, then the timed calls alternate between them (one call of each per round), so a slow
spell of a shared machine lands on all of them; the medians over rounds and their ratios
are reported.

  PYTHONPATH=. python benchmarks/candidate_scoring.py
  PYTHONPATH=. python benchmarks/candidate_scoring.py --resolution=100 --num_gaussians=5000
"""

import os
import platform
import statistics
import time

from absl import app, flags

_N = flags.DEFINE_integer("num_gaussians", 2000, "Gaussians of the (random) model.")
_RES = flags.DEFINE_integer("resolution", 64, "Square image size of the candidates.")
_CANDS = flags.DEFINE_integer("num_candidates", 32, "Candidates scored per timed call.")
_M = flags.DEFINE_integer("samples", 2, "M, samples of ours (paper: 2).")
_K = flags.DEFINE_list("probes", ["1", "4"], "FisherRF probes per candidate to time.")
_REPEATS = flags.DEFINE_integer("repeats", 7, "Timed rounds (median); one call per scorer each.")
_OUT = flags.DEFINE_string("out", "results/bench_candidate_scoring.json", "JSON output.")


def _median_seconds_alternating(fns, repeats):
  """Median seconds per call of each fn, the calls alternating between them round by round."""
  import jax

  for fn in fns.values():
    jax.block_until_ready(fn())  # compile + warm up
  times = {name: [] for name in fns}
  for _ in range(repeats):
    for name, fn in fns.items():
      t0 = time.perf_counter()
      jax.block_until_ready(fn())
      times[name].append(time.perf_counter() - t0)
  return {name: statistics.median(t) for name, t in times.items()}


def run():
  import jax
  import jax.numpy as jnp
  import numpy as np

  from mfsample import uncertainty as unc
  from mfsample.model import GROUPS, SamplerSpec, init_model
  from mfsample.planning import fisher, poses
  from mfsample.renderer import RenderSettings

  rng = np.random.default_rng(0)
  n, res, b = _N.value, _RES.value, _CANDS.value
  points = rng.normal(size=(n, 3))
  points *= (rng.uniform(size=(n, 1)) ** (1 / 3)) / np.linalg.norm(points, axis=1, keepdims=True)
  bounds = tuple(zip(GROUPS, (1.0, 20.0, 2.0, 20.0, 0.5, 0.5), strict=True))
  model = init_model(jax.random.PRNGKey(0), points,
                     spec=SamplerSpec("lowrank", 2, GROUPS, bounds), sh_degree=0,
                     init_scales={g: 0.01 for g in GROUPS}, init_opacity=0.5,
                     colors=rng.uniform(size=(n, 3)))
  sphere = poses.SphereSpec(radius=3.0, width=res, height=res)
  uv = poses.random_uv(rng, b, sphere).astype(np.float32)
  cams = poses.spherical_camera(jnp.asarray(uv), sphere)
  bg = jnp.ones(3)
  z = unc.uncertainty_z(model, _M.value, 6174)
  # The smallest power-of-two budget that holds every candidate (a forward render's cost
  # grows with the budget: the tile sort spans all of it).
  _, settings = unc.score_cameras(model, cams, z,
                                  settings=RenderSettings(max_intersections=512), background=bg)
  det = model.replace(spec=SamplerSpec("deterministic"), params=model.params._replace(
      spread={}), signs={})

  def ours():
    return unc.score_cameras(model, cams, z, settings=settings, background=bg)[0].values

  result = {"num_gaussians": n, "resolution": res, "num_candidates": b, "samples": _M.value,
            "budget": settings.max_intersections, "device": str(jax.devices()[0]),
            "platform": platform.platform(), "cpu_count": os.cpu_count()}
  inverse = jax.tree.map(lambda x: jnp.ones_like(x), {g: det.params.mean[g]
                                                      for g in fisher.DEFAULT_GROUPS
                                                      if g in det.params.mean})

  def fisher_scorer(k):
    @jax.jit
    def fisher_candidates(key):
      def one(camera, inv):
        h, _ = fisher.fisher_diagonal(det, camera, key, num_probes=k, settings=settings,
                                      background=bg, groups=tuple(inv))
        return sum(jnp.sum(h[g] * inv[g]) for g in h)
      return unc.map_cameras(one, cams, inverse)
    return lambda: fisher_candidates(jax.random.PRNGKey(1))

  probes = [int(x) for x in _K.value]
  scorers = {"ours": ours, **{f"fisher_{k}": fisher_scorer(k) for k in probes}}
  seconds = _median_seconds_alternating(scorers, _REPEATS.value)
  t_ours = seconds["ours"] / b
  result["ours_seconds_per_candidate"] = t_ours
  result["repeats"] = _REPEATS.value
  print(f"ours (M={_M.value} forward renders): {1e3 * t_ours:.2f} ms per candidate")
  for k in probes:
    t_f = seconds[f"fisher_{k}"] / b
    result[f"fisher_{k}_probes_seconds_per_candidate"] = t_f
    result[f"ratio_fisher_{k}_probes_over_ours"] = t_f / t_ours
    print(f"FisherRF ({k} probe backward passes): {1e3 * t_f:.2f} ms per candidate, "
          f"{t_f / t_ours:.2f}x ours")
  return result


def main(argv):
  del argv
  from mfsample._json import write_json
  write_json(_OUT.value, run())
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
