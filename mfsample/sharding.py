"""Batches split over devices: `jax.shard_map` over the local devices, chunks within each.

Candidate scoring, U over lights and the Fisher baseline evaluate one function per camera
(or per sample) of a batch. `map_sharded` runs such a function over a batch inside jit:
`chunk_size` elements at a time (`jax.lax.map` over vmapped chunks, so memory holds one
chunk), and with `num_devices` > 1 the batch split over the first devices with
`jax.shard_map` (the other arguments replicated).
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import AxisType, Mesh, PartitionSpec

from mfsample.camera import Camera


def map_sharded(fn, xs, *args, chunk_size=1, num_devices=1):
  """fn(x, *args) for every x of a batch `xs` (a pytree with a leading axis); inside jit.

  The batch is processed `chunk_size` at a time (`jax.lax.map` with a vmapped chunk), so
  memory holds one chunk. With `num_devices` > 1 it is split over the first `num_devices`
  devices with `jax.shard_map` (args replicated) and each device maps over its share. The
  batch is padded with copies of its last element to a multiple of num_devices *
  chunk_size; the padding is dropped from the result.

  Under vmap (chunk_size > 1) the renderer skips unused budget only as far as the whole
  chunk allows; chunk_size = 1 is the safe choice on a CPU, larger chunks pay off on
  accelerators.

  Args:
    fn: (one element of xs, *args) -> pytree of arrays.
    xs: pytree whose leaves share a leading axis [B] (a batched `Camera`, M `Gaussians`).
    *args: replicated arguments (pytrees).
    chunk_size: elements vmapped together.
    num_devices: devices to shard the batch over (static).

  Returns:
    fn's pytree with a leading [B] axis.
  """
  b = jax.tree.leaves(xs)[0].shape[0]
  per_device = chunk_size * math.ceil(b / (num_devices * chunk_size))
  total = per_device * num_devices
  if total != b:
    idx = jnp.minimum(jnp.arange(total), b - 1)
    xs = jax.tree.map(lambda x: x[idx], xs)

  def local(batch, *a):
    # batch_size=1 would still vmap (over a unit axis) and lose the renderer's skipping.
    size = None if chunk_size == 1 else chunk_size
    return jax.lax.map(lambda x: fn(x, *a), batch, batch_size=size)

  if num_devices == 1:
    out = local(xs, *args)
  else:
    # Auto axes: inside jit, XLA moves the (unsharded) inputs onto the mesh as needed.
    mesh = Mesh(np.asarray(jax.devices()[:num_devices]), ("batch",),
                axis_types=(AxisType.Auto,))
    specs = (PartitionSpec("batch"),) + (PartitionSpec(),) * len(args)
    out = jax.shard_map(local, mesh=mesh, in_specs=specs, out_specs=PartitionSpec("batch"),
                        check_vma=False)(xs, *args)
  return jax.tree.map(lambda x: x[:b], out)


def map_cameras(fn, cameras: Camera, *args, chunk_size=1, num_devices=1):
  """`map_sharded` over a `Camera` batched over one axis [B]: fn(camera, *args) each."""
  if len(cameras.batch_shape) != 1:
    raise ValueError(f"map_cameras takes a Camera batched over one axis, got "
                     f"{cameras.batch_shape}")
  return map_sharded(fn, cameras, *args, chunk_size=chunk_size, num_devices=num_devices)


def default_num_devices(num_items):
  """Devices to shard over: all of them, but not more than there are items."""
  return max(1, min(jax.device_count(), int(num_items)))
