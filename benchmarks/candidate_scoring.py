"""Time to score one candidate view: ours (M forward renders) against FisherRF (backward passes).

Ours scores a candidate with M forward renders of sampled models (Eq. 10); FisherRF needs
the diagonal Fisher information of the candidate's render, i.e. backward passes (here K
Rademacher probes, one vector-Jacobian product each). Both run on the same random model,
the same candidate cameras and the same render settings, in one process. Every scorer is
compiled first, then the timed calls alternate between them (one call of each per round),
so a slow spell of a shared machine lands on all of them; the medians over rounds and their
ratios are reported.

  python benchmarks/candidate_scoring.py
  python benchmarks/candidate_scoring.py --resolution=200 --num_gaussians=10000 \
      --out=workdirs/benchmarks/candidate_scoring_200.json
"""

import statistics
import time

from absl import app, flags

_N = flags.DEFINE_integer("num_gaussians", 2000, "Gaussians of the (random) model.")
_RES = flags.DEFINE_integer("resolution", 64, "Square image size of the candidates.")
_CANDS = flags.DEFINE_integer("num_candidates", 32, "Candidates scored per timed call.")
_M = flags.DEFINE_integer("samples", 2, "M, samples of ours (paper: 2).")
_K = flags.DEFINE_list("probes", ["1", "4"], "FisherRF probes per candidate to time.")
_REPEATS = flags.DEFINE_integer("repeats", 7, "Timed rounds (median); one call per scorer each.")
_OUT = flags.DEFINE_string("out", "workdirs/benchmarks/candidate_scoring.json", "JSON output.")


def median_seconds_alternating(fns, repeats):
  """{name: median seconds per call} of every fn of `fns` ({name: fn()}), each compiled and
  warmed up first, then called in turn, one call of each per round, for `repeats` rounds."""
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


def random_model(num_gaussians, seed=0):
  """A rank-2 model of `num_gaussians` random Gaussians in the unit ball (SH degree 0)."""
  import jax
  import numpy as np

  from mfsample.groups import GROUPS
  from mfsample.model import init_model
  from mfsample.samplers import SamplerSpec

  rng = np.random.default_rng(seed)
  points = rng.normal(size=(num_gaussians, 3))
  points *= (rng.uniform(size=(num_gaussians, 1)) ** (1 / 3)) / np.linalg.norm(
      points, axis=1, keepdims=True)
  return init_model(jax.random.PRNGKey(seed), points,
                    spec=SamplerSpec.default(GROUPS, kind="lowrank", rank=2), sh_degree=0,
                    init_scales={g: 0.01 for g in GROUPS}, init_opacity=0.5,
                    colors=rng.uniform(size=(num_gaussians, 3)))


def run(*, num_gaussians, resolution, num_candidates, samples, probes, repeats):
  """Seconds per candidate of ours and of FisherRF with each probe count, and their ratios.

  Args:
    num_gaussians: Gaussians of the random model (`random_model`).
    resolution: square side of the candidate images.
    num_candidates: random candidate cameras on a sphere of radius 3, scored per call.
    samples: M of ours.
    probes: FisherRF probe counts K to time.
    repeats: timed rounds (one call of each scorer per round; medians over rounds).

  Returns:
    {the arguments, budget (intersections per render: the smallest power of two that
    holds every candidate), ours_seconds_per_candidate, and for each K:
    fisher_{K}_probes_seconds_per_candidate, ratio_fisher_{K}_probes_over_ours}.
  """
  import jax
  import jax.numpy as jnp
  import numpy as np

  from mfsample import view_uncertainty as unc
  from mfsample.baselines import fisher
  from mfsample.planning import poses
  from mfsample.renderer import RenderSettings
  from mfsample.samplers import SamplerSpec, sample_z
  from mfsample.sharding import map_cameras

  rng = np.random.default_rng(0)
  model = random_model(num_gaussians)
  sphere = poses.SphereSpec(radius=3.0, width=resolution, height=resolution)
  uv = poses.random_uv(rng, num_candidates, sphere).astype(np.float32)
  cams = poses.spherical_camera(jnp.asarray(uv), sphere)
  bg = jnp.ones(3)
  z = sample_z(model, samples, seed=6174)
  # The smallest power-of-two budget that holds every candidate (a forward render's cost
  # grows with the budget: the tile sort spans all of it).
  _, settings = unc.score_cameras(model, cams, z,
                                  settings=RenderSettings(max_intersections=512), background=bg)
  det = model.replace(spec=SamplerSpec("deterministic"), params=model.params._replace(
      b_hat={}), signs={})

  def ours():
    return unc.score_cameras(model, cams, z, settings=settings, background=bg)[0].values

  inverse = jax.tree.map(jnp.ones_like, {g: det.params.mean[g] for g in fisher.DEFAULT_GROUPS
                                         if g in det.params.mean})

  def fisher_scorer(k):
    @jax.jit
    def fisher_candidates(key):
      def one(camera, inv):
        h, _ = fisher.fisher_diagonal(det, camera, key, num_probes=k, settings=settings,
                                      background=bg, groups=tuple(inv))
        return sum(jnp.sum(h[g] * inv[g]) for g in h)
      return map_cameras(one, cams, inverse)
    return lambda: fisher_candidates(jax.random.PRNGKey(1))

  probes = [int(k) for k in probes]
  scorers = {"ours": ours, **{f"fisher_{k}": fisher_scorer(k) for k in probes}}
  seconds = median_seconds_alternating(scorers, repeats)
  t_ours = seconds["ours"] / num_candidates
  result = {"num_gaussians": num_gaussians, "resolution": resolution,
            "num_candidates": num_candidates, "samples": samples, "probes": probes,
            "repeats": repeats, "budget": settings.max_intersections,
            "ours_seconds_per_candidate": t_ours}
  for k in probes:
    t_f = seconds[f"fisher_{k}"] / num_candidates
    result[f"fisher_{k}_probes_seconds_per_candidate"] = t_f
    result[f"ratio_fisher_{k}_probes_over_ours"] = t_f / t_ours
  return result


def main(argv):
  del argv
  from mfsample._bench import machine
  from mfsample._json import write_json

  result = run(num_gaussians=_N.value, resolution=_RES.value, num_candidates=_CANDS.value,
               samples=_M.value, probes=_K.value, repeats=_REPEATS.value)
  t_ours = result["ours_seconds_per_candidate"]
  print(f"ours (M={_M.value} forward renders): {1e3 * t_ours:.2f} ms per candidate")
  for k in result["probes"]:
    t_f = result[f"fisher_{k}_probes_seconds_per_candidate"]
    print(f"FisherRF ({k} probe backward passes): {1e3 * t_f:.2f} ms per candidate, "
          f"{result[f'ratio_fisher_{k}_probes_over_ours']:.2f}x ours")
  write_json(_OUT.value, {"machine": machine(), **result})
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
