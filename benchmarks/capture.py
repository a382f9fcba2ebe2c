"""Benchmark of ground-truth captures: seconds per capture per Mitsuba variant and spp.

  PYTHONPATH=. python benchmarks/capture.py                 # spp sweep + SH basis
  PYTHONPATH=. python benchmarks/capture.py --pool          # + the default pool (150 views)
  PYTHONPATH=. python benchmarks/capture.py --quick         # tiny, for a smoke test

Prints a table and writes JSON (default results/capture_benchmark.json). Variants:
scalar_rgb always; llvm_ad_rgb when it can render here (needs libllvm19 on Debian).
`--pool` captures the default scene's candidate pool (100 views) and 50 test views at
100x100 with the default spp into a fresh cache folder, then again from that cache.
"""

import json
import os
import tempfile
import time
from pathlib import Path

from absl import app, flags

from mfsample import scenes

_OUTPUT = flags.DEFINE_string("output", "results/capture_benchmark.json", "JSON output path.")
_POOL = flags.DEFINE_bool("pool", False, "Also time the default 100 + 50 view pool capture.")
_QUICK = flags.DEFINE_bool("quick", False, "Tiny sizes and counts (smoke test).")


def _time_views(scene, cameras, spp, variant):
  """Seconds for capture_views without the cache (scene build included once)."""
  start = time.perf_counter()
  scenes.capture_views(scene, cameras, spp=spp, variant=variant, cache=False, progress=False)
  return time.perf_counter() - start


def main(argv):
  del argv
  quick = _QUICK.value
  size = 16 if quick else 100
  num = 2 if quick else 6
  spps = (4, 16) if quick else (4, 16, 36, 64)
  scene = scenes.get_scene()
  variants = ["scalar_rgb"] + (["llvm_ad_rgb"] if scenes.llvm_available() else [])
  cameras = scene.candidate_cameras(size, size, num=num, seed=123)
  report = {
      "scene": scene.name, "width": size, "height": size, "views_per_point": num,
      "default_spp": scenes.DEFAULT_SPP, "default_sh_spp": scenes.DEFAULT_SH_SPP,
      "cpu_count": os.cpu_count(), "load_average_before": os.getloadavg(),
      "variants": variants, "rgbad": [], "sh_basis": [],
  }
  print(f"{scene.name} at {size}x{size}, {num} views per point, variants {variants}")
  print(f"{'variant':<12} {'spp':>5} {'s/capture':>10}")
  for variant in variants:
    # Warm-up: the first capture pays for the scene build and, for llvm, kernel compilation.
    first = _time_views(scene, cameras[:1], spps[0], variant)
    report.setdefault("first_capture_seconds", {})[variant] = first
    for spp in spps:
      seconds = _time_views(scene, cameras, spp, variant) / num
      report["rgbad"].append({"variant": variant, "spp": spp, "seconds_per_capture": seconds})
      print(f"{variant:<12} {spp:>5} {seconds:>10.3f}")
    start = time.perf_counter()
    scenes.capture_sh_basis(scene, cameras[0], degree=3, spp=scenes.DEFAULT_SH_SPP,
                            variant=variant, cache=False)
    seconds = time.perf_counter() - start
    report["sh_basis"].append({"variant": variant, "spp": scenes.DEFAULT_SH_SPP, "degree": 3,
                               "seconds_per_capture": seconds})
    print(f"{variant:<12} {scenes.DEFAULT_SH_SPP:>5} {seconds:>10.3f}  (SH basis, 16 images)")

  if _POOL.value:
    pool_size, n_cand, n_test = (16, 4, 2) if quick else (100, 100, 50)
    with tempfile.TemporaryDirectory() as cache_dir:
      timings = {}
      for attempt in ("fresh", "cached"):
        start = time.perf_counter()
        scenes.capture_views(scene, scene.candidate_cameras(pool_size, pool_size, n_cand),
                             cache_dir=cache_dir, progress=not quick)
        scenes.capture_views(scene, scene.test_cameras(pool_size, pool_size, n_test),
                             cache_dir=cache_dir, progress=not quick)
        timings[attempt] = time.perf_counter() - start
    report["pool"] = {"views": n_cand + n_test, "size": pool_size,
                      "variant": scenes.resolve_variant(), "spp": scenes.DEFAULT_SPP,
                      "seconds": timings["fresh"], "cached_seconds": timings["cached"]}
    print(f"pool: {n_cand} + {n_test} views at {pool_size}x{pool_size}, spp "
          f"{scenes.DEFAULT_SPP}, {scenes.resolve_variant()}: {timings['fresh']:.1f} s, "
          f"from the cache {timings['cached']:.2f} s")

  report["load_average_after"] = os.getloadavg()
  out = Path(_OUTPUT.value)
  out.parent.mkdir(parents=True, exist_ok=True)
  out.write_text(json.dumps(report, indent=2))
  print(f"wrote {out}")


if __name__ == "__main__":
  app.run(main)
