"""Two parts of every training step, each timed against what it replaced, in one process.

- SSIM (the loss's structural term; `mfsample.metrics.ssim`): the 11-tap Gaussian window as
  banded matrix products, against dm-pix's default filter (vmapped 1D convolutions); value
  and gradient w.r.t. the prediction, jitted, at several image sizes; also both forms of
  our filter (one product per axis, blocks) at every size, where its switch is chosen.
- The tile sort (`mfsample.render.tiles`): (tile, depth rank) pairs packed into one int32
  key and sorted once, against the stable two-array sort it replaced, at several pair
  counts (the renderer sorts its whole intersection budget every render).

Each figure is the median of `--repeats` calls after a warm-up; ratios are old / new within
the same run. The largest differences from the replaced versions are printed too.

  PYTHONPATH=. python benchmarks/step_parts.py --out=results/step_parts_cpu.json
"""

import json
import platform
import statistics
import time

from absl import app, flags

_SIZES = flags.DEFINE_list("ssim_sizes", ["64", "200", "400", "800", "1600"],
                          "Square image sides.")
_PAIRS = flags.DEFINE_list("pairs", ["65536", "1048576"],
                           "Intersection budgets (pairs sorted per render).")
_REPEATS = flags.DEFINE_integer("repeats", 9, "Timed calls per figure (median).")
_OUT = flags.DEFINE_string("out", None, "Optional JSON output.")


def _median_ms(fn, *args):
  import jax

  jax.block_until_ready(fn(*args))  # compile and warm up
  times = []
  for _ in range(_REPEATS.value):
    start = time.perf_counter()
    jax.block_until_ready(fn(*args))
    times.append(time.perf_counter() - start)
  return 1e3 * statistics.median(times)


def _ssim_rows():
  import dm_pix
  import jax
  import jax.numpy as jnp

  from mfsample import metrics

  rows = []
  for size in map(int, _SIZES.value):
    keys = jax.random.split(jax.random.PRNGKey(size), 2)
    target = jax.random.uniform(keys[0], (size, size, 3))
    pred = 0.7 * target + 0.3 * jax.random.uniform(keys[1], (size, size, 3))
    ours = jax.jit(jax.value_and_grad(lambda p, t=target: metrics.ssim(p, t)))
    old = jax.jit(jax.value_and_grad(lambda p, t=target: dm_pix.ssim(p, t)))
    (v_ours, g_ours), (v_old, g_old) = ours(pred), old(pred)
    rows.append({
        "size": size,
        "ours_ms": _median_ms(ours, pred),
        # Both forms of our filter at every size: where one product per axis stops paying.
        **{f"{form}_ms": _median_ms(_ssim_in_form(metrics, form, target), pred)
           for form in ("one_product", "blocks")},
        "dm_pix_default_ms": _median_ms(old, pred),
        "max_value_difference": float(jnp.abs(v_ours - v_old)),
        "max_gradient_difference": float(jnp.max(jnp.abs(g_ours - g_old))),
        "max_gradient": float(jnp.max(jnp.abs(g_old))),
    })
  return rows


def _ssim_in_form(metrics, form, target):
  """Jitted value and gradient of our SSIM with its window filter forced into `form`
  ("one_product" per axis, or "blocks"), whatever the image size."""
  import jax

  def loss(p):
    saved = metrics._ONE_PRODUCT_MAX
    metrics._ONE_PRODUCT_MAX = 1 << 30 if form == "one_product" else 0
    try:  # read while tracing, so the compiled function keeps the forced form
      return metrics.ssim(p, target)
    finally:
      metrics._ONE_PRODUCT_MAX = saved

  return jax.jit(jax.value_and_grad(loss))


def _sort_rows():
  import jax
  import jax.numpy as jnp
  import numpy as np

  from mfsample.render.tiles import _sort_by_tile_then_rank

  rows = []
  num_tiles, num_gaussians = 625, 100_000  # 400 x 400 in 16-pixel tiles, 100k Gaussians
  for pairs in map(int, _PAIRS.value):
    rng = np.random.default_rng(pairs)
    # As the renderer emits them: ranks ascending (front to back), tiles in any order.
    rank = jnp.asarray(np.sort(rng.integers(0, num_gaussians, pairs)), jnp.int32)
    tile = jnp.asarray(rng.integers(0, num_tiles + 1, pairs), jnp.int32)
    ours = jax.jit(lambda t, r: _sort_by_tile_then_rank(t, r, num_tiles, num_gaussians))
    old = jax.jit(lambda t, r: jax.lax.sort((t, r), num_keys=1, is_stable=True))
    same = all(bool(jnp.array_equal(a, b))
               for a, b in zip(ours(tile, rank), old(tile, rank), strict=True))
    rows.append({"pairs": pairs, "packed_key_ms": _median_ms(ours, tile, rank),
                 "stable_two_array_ms": _median_ms(old, tile, rank), "identical": same})
  return rows


def main(argv):
  del argv
  import jax

  ssim, sort = _ssim_rows(), _sort_rows()
  print("| image | SSIM value+grad, ours ms | one product ms | blocks ms | dm-pix default ms "
        "| ratio | max |dvalue| | max |dgrad| / max |grad| |")
  print("|---:|---:|---:|---:|---:|---:|---:|---:|")
  for r in ssim:
    print(f"| {r['size']}^2 | {r['ours_ms']:.2f} | {r['one_product_ms']:.2f} "
          f"| {r['blocks_ms']:.2f} | {r['dm_pix_default_ms']:.2f} "
          f"| {r['dm_pix_default_ms'] / r['ours_ms']:.1f}x | {r['max_value_difference']:.1e} "
          f"| {r['max_gradient_difference'] / r['max_gradient']:.1e} |")
  print()
  print("| pairs | packed int32 key ms | stable two-array sort ms | ratio | identical |")
  print("|---:|---:|---:|---:|---|")
  for r in sort:
    print(f"| {r['pairs']} | {r['packed_key_ms']:.2f} | {r['stable_two_array_ms']:.2f} "
          f"| {r['stable_two_array_ms'] / r['packed_key_ms']:.1f}x | {r['identical']} |")
  if _OUT.value:
    with open(_OUT.value, "w") as f:
      json.dump({"ssim": ssim, "sort": sort, "device": str(jax.devices()[0]),
                 "machine": platform.processor() or platform.machine(),
                 "repeats": _REPEATS.value}, f, indent=1)
    print(f"wrote {_OUT.value}")


if __name__ == "__main__":
  app.run(main)
