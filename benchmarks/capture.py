"""Seconds per ground-truth capture per Mitsuba variant and samples per pixel (spp).

  python benchmarks/capture.py                 # spp sweep + SH basis
  python benchmarks/capture.py --pool          # + the default pool (150 views)
  python benchmarks/capture.py --quick         # tiny, for a smoke test

For each variant (scalar_rgb always; llvm_ad_rgb when it can render here, which needs
libllvm19 on Debian) one untimed capture pays for the scene build and, for llvm, kernel
compilation; then the same views are captured at each spp, without the cache, and the
mean seconds per capture is reported, as is one SH basis capture (the 2 (d + 1)^2 - 1
renders of `capture_sh_basis`). `--pool` captures the default scene's candidate pool (100
views) and 50 test views at 100 x 100 with the default spp into a fresh cache folder, then
again from that cache. Prints a table and writes JSON.
"""

import tempfile
import time

from absl import app, flags

_OUT = flags.DEFINE_string("out", "workdirs/benchmarks/capture.json", "JSON output path.")
_POOL = flags.DEFINE_bool("pool", False, "Also time the default 100 + 50 view pool capture.")
_QUICK = flags.DEFINE_bool("quick", False, "Tiny sizes and counts (smoke test).")


def _seconds_for_views(scene, cameras, spp, variant):
  """Seconds for `capture_views` without the cache (the scene is built once per call)."""
  from mfsample import scenes

  start = time.perf_counter()
  scenes.capture_views(scene, cameras, spp=spp, variant=variant, cache=False, progress=False)
  return time.perf_counter() - start


def spp_sweep(scene, *, size, views, spps, variants, sh_degree=3, sh_spp=None, log=print):
  """Seconds per capture of `scene` per Mitsuba variant and spp, and per SH basis capture.

  Args:
    scene: a `mfsample.scenes.Scene`.
    size: square image side in pixels.
    views: candidate cameras captured per (variant, spp) (seed 123).
    spps: samples per pixel to time (perfect squares).
    variants: Mitsuba variants ("scalar_rgb", "llvm_ad_rgb").
    sh_degree: SH degree of the basis capture.
    sh_spp: spp of the basis capture (default `scenes.DEFAULT_SH_SPP`).
    log: called with one line per measurement.

  Returns:
    {scene, width, height, views_per_point, variants, first_capture_seconds {variant: s},
     rgbad: [{variant, spp, seconds_per_capture}],
     sh_basis: [{variant, spp, degree, images, seconds_per_capture}]}.
  """
  from mfsample import scenes

  sh_spp = scenes.DEFAULT_SH_SPP if sh_spp is None else sh_spp
  cameras = scene.candidate_cameras(size, size, num=views, seed=123)
  report = {"scene": scene.name, "width": size, "height": size, "views_per_point": views,
            "variants": list(variants), "first_capture_seconds": {}, "rgbad": [],
            "sh_basis": []}
  for variant in variants:
    # Untimed: the first capture pays for the scene build and, for llvm, kernel compilation.
    report["first_capture_seconds"][variant] = _seconds_for_views(scene, cameras[:1],
                                                                  spps[0], variant)
    for spp in spps:
      seconds = _seconds_for_views(scene, cameras, spp, variant) / views
      report["rgbad"].append({"variant": variant, "spp": spp, "seconds_per_capture": seconds})
      log(f"{variant:<12} {spp:>5} {seconds:>10.3f}")
    start = time.perf_counter()
    basis = scenes.capture_sh_basis(scene, cameras[0], degree=sh_degree, spp=sh_spp,
                                    variant=variant, cache=False)
    seconds = time.perf_counter() - start
    report["sh_basis"].append({"variant": variant, "spp": sh_spp, "degree": sh_degree,
                               "images": len(basis), "seconds_per_capture": seconds})
    log(f"{variant:<12} {sh_spp:>5} {seconds:>10.3f}  (SH basis, {len(basis)} images)")
  return report


def pool_capture(scene, *, size, candidates, test, cache_dir, progress=False):
  """Seconds to capture `candidates` + `test` views at `size` x `size` with the default spp
  and variant into the empty folder `cache_dir`, then again from that cache.

  Returns:
    {views, size, variant, spp, seconds, cached_seconds}.
  """
  from mfsample import scenes

  timings = {}
  for attempt in ("fresh", "cached"):
    start = time.perf_counter()
    scenes.capture_views(scene, scene.candidate_cameras(size, size, candidates),
                         cache_dir=cache_dir, progress=progress)
    scenes.capture_views(scene, scene.test_cameras(size, size, test), cache_dir=cache_dir,
                         progress=progress)
    timings[attempt] = time.perf_counter() - start
  return {"views": candidates + test, "size": size, "variant": scenes.resolve_variant(),
          "spp": scenes.DEFAULT_SPP, "seconds": timings["fresh"],
          "cached_seconds": timings["cached"]}


def main(argv):
  del argv
  import mitsuba

  from mfsample import scenes
  from mfsample._bench import load_average, machine
  from mfsample._json import write_json

  quick = _QUICK.value
  scene = scenes.get_scene()
  variants = ["scalar_rgb"] + (["llvm_ad_rgb"] if scenes.llvm_available() else [])
  size, views = (16, 2) if quick else (100, 6)
  print(f"{scene.name} at {size}x{size}, {views} views per point, variants {variants}")
  print(f"{'variant':<12} {'spp':>5} {'s/capture':>10}")
  report = {"machine": {**machine(), "mitsuba": mitsuba.__version__},
            "default_spp": scenes.DEFAULT_SPP, "default_sh_spp": scenes.DEFAULT_SH_SPP,
            "load_average_before": list(load_average())}
  report.update(spp_sweep(scene, size=size, views=views,
                          spps=(4, 16) if quick else (4, 16, 36, 64), variants=variants,
                          log=lambda line: print(line, flush=True)))
  if _POOL.value:
    pool_size, candidates, test = (16, 4, 2) if quick else (100, 100, 50)
    with tempfile.TemporaryDirectory() as cache_dir:
      pool = pool_capture(scene, size=pool_size, candidates=candidates, test=test,
                          cache_dir=cache_dir, progress=not quick)
    report["pool"] = pool
    print(f"pool: {candidates} + {test} views at {pool_size}x{pool_size}, spp {pool['spp']}, "
          f"{pool['variant']}: {pool['seconds']:.1f} s, from the cache "
          f"{pool['cached_seconds']:.2f} s")
  report["load_average_after"] = list(load_average())
  write_json(_OUT.value, report)
  print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
