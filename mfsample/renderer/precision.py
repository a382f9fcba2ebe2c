"""The matrix-product precision of every matmul in the renderer: full float32.

On NVIDIA GPUs since Ampere, XLA runs a float32 matmul with the default precision in TF32
(10 mantissa bits, relative error ~1e-3). In the renderer that error is not a rounding
detail: a camera-space centre off by 1e-3 of its coordinates moves a splat by a fraction
of a pixel, and a prefix sum of log-transmittance off by 1e-3 of ~9 (log 1e-4) changes
transmittance by ~1%. The CPU, which computes float32 products in full precision whatever
the setting, would then disagree with the GPU by far more than rounding. Every product in
`mfsample.render` therefore passes this precision explicitly. The products are small (3x3
rotations, chunk-sized prefix sums), so full float32 costs little on a GPU, and nothing on
a CPU. Pallas kernels need no setting: the compositing kernel has no matrix product.
"""

import jax

MATMUL = jax.lax.Precision.HIGHEST
