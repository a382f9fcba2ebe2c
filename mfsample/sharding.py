"""Batches split over devices: `jax.shard_map` over the devices of every process, chunks within.

Candidate scoring, U over lights and the Fisher baseline evaluate one function per camera
(or per sample) of a batch. `map_sharded` runs such a function over a batch inside jit:
`chunk_size` elements at a time (`jax.lax.map` over vmapped chunks, so memory holds one
chunk), and with `num_devices` > 1 the batch split over devices with `jax.shard_map` (the
other arguments replicated). `reduce_sharded` does the same for a batch whose results are
summed (and maxed) rather than kept: the data-parallel training step's views.

The devices are those of every process (`jax.devices()`): in a multi-process run
(`mfsample.distributed`) a mesh spans the processes, ordered so that its first devices
belong to different processes (`mesh_devices`), and results are replicated on every
device of the mesh, so every process reads them. A result is committed to its mesh, and a
jitted function refuses inputs committed to a mesh other than its own: so every batch is
split over one mesh, all devices (`default_num_devices`), padded to a multiple of their
number, and padded elements are skipped (`lax.cond`) rather than computed.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import AxisType, Mesh, NamedSharding, PartitionSpec

from mfsample.camera import Camera

AXIS = "batch"  # the mesh axis the batch is split over


def mesh_devices():
  """Every device of every process, in the order meshes take them: round-robin over the
  processes (each process's first device, then each one's second, ...), so that a mesh of
  n >= (number of processes) devices has a device in every process. With one process:
  `jax.devices()`."""
  by_process = {}
  for d in jax.devices():
    by_process.setdefault(d.process_index, []).append(d)
  columns = max(len(v) for v in by_process.values())
  return [v[i] for i in range(columns) for _, v in sorted(by_process.items()) if i < len(v)]


def batch_mesh(num_devices):
  """A one-axis (`AXIS`) mesh over the first `num_devices` of `mesh_devices()`."""
  devices = mesh_devices()
  if not 1 <= num_devices <= len(devices):
    raise ValueError(f"num_devices must be in 1..{len(devices)} (the devices of every "
                     f"process), got {num_devices}")
  # Auto axes: inside jit, XLA moves the (unsharded) inputs onto the mesh as needed.
  return Mesh(np.asarray(devices[:num_devices]), (AXIS,), axis_types=(AxisType.Auto,))


def replicated(tree, num_devices):
  """`tree` placed on every device of `batch_mesh(num_devices)` (once, not at every call of
  a jitted function that splits a batch over them). Host arrays in a multi-process run must
  be equal in every process: each contributes its own copy."""
  if num_devices == 1:
    return tree
  return jax.device_put(tree, NamedSharding(batch_mesh(num_devices), PartitionSpec()))


def host_local(tree):
  """`tree` as arrays of this process alone (uncommitted, on its default device).

  An array replicated over a mesh (the data-parallel step's state) is committed to that
  mesh: a later function splitting a batch over *another* mesh refuses it. Bringing it back
  to the host once (at the end of training) lets any later function place it freely.
  """
  return jax.tree.map(lambda x: jnp.asarray(np.asarray(x)) if isinstance(x, jax.Array) else x,
                      tree)


def _pad(xs, total):
  """The batch `xs` (leading axis [B]) padded to `total` with copies of its last element."""
  b = jax.tree.leaves(xs)[0].shape[0]
  if total == b:
    return xs
  idx = jnp.minimum(jnp.arange(total), b - 1)
  return jax.tree.map(lambda x: x[idx], xs)


def _skipping_padding(fn, example, args):
  """(x, real) -> `fn(x, *args)` where `real`, else zeros of fn's output (nothing computed)."""
  shapes = jax.eval_shape(fn, example, *args)

  def one(x, real):
    return jax.lax.cond(real, lambda: fn(x, *args),
                        lambda: jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes))
  return one


def _replicate_outputs(out, mesh):
  # Every process (and every device) holds the whole result: a multi-process run reads it
  # in each process, and a later function may use it on any mesh.
  return jax.lax.with_sharding_constraint(out, NamedSharding(mesh, PartitionSpec()))


def map_sharded(fn, xs, *args, chunk_size=1, num_devices=1):
  """`fn(x, *args)` for every x of a batch `xs` (a pytree with a leading axis); inside jit.

  The batch is processed `chunk_size` at a time (`jax.lax.map` with a vmapped chunk), so
  memory holds one chunk. With `num_devices` > 1 it is split over the first `num_devices`
  devices of `mesh_devices()` with `jax.shard_map` (args replicated) and each device maps
  over its share; the result is replicated on every device of the mesh. The batch is padded
  with copies of its last element to a multiple of num_devices * chunk_size; with
  chunk_size = 1 a padded element is skipped, not computed, and the padding is dropped
  from the result.

  Under vmap (chunk_size > 1) the renderer skips unused budget only as far as the whole
  chunk allows; chunk_size = 1 is the safe choice on a CPU, larger chunks pay off on
  accelerators.

  Args:
    fn: `(one element of xs, *args)` -> pytree of arrays.
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
  xs = _pad(xs, total)
  real = jnp.arange(total) < b
  skip = chunk_size == 1 and total > b  # (a vmapped chunk would compute both branches)

  def local(batch, keep, *a):
    if skip:
      one = _skipping_padding(fn, jax.tree.map(lambda x: x[0], batch), a)
      return jax.lax.map(lambda item: one(*item), (batch, keep))
    # batch_size=1 would still vmap (over a unit axis) and lose the renderer's skipping.
    size = None if chunk_size == 1 else chunk_size
    return jax.lax.map(lambda x: fn(x, *a), batch, batch_size=size)

  if num_devices == 1:
    out = local(xs, real, *args)
  else:
    mesh = batch_mesh(num_devices)
    specs = (PartitionSpec(AXIS), PartitionSpec(AXIS)) + (PartitionSpec(),) * len(args)
    out = jax.shard_map(local, mesh=mesh, in_specs=specs, out_specs=PartitionSpec(AXIS),
                        check_vma=False)(xs, real, *args)
    out = _replicate_outputs(out, mesh)
  return jax.tree.map(lambda x: x[:b], out)


def _lowest(x):
  """The identity of max for `x`'s dtype."""
  if jnp.issubdtype(x.dtype, jnp.floating):
    return jnp.full_like(x, -jnp.inf)
  return jnp.full_like(x, jnp.iinfo(x.dtype).min)


def reduce_sharded(fn, xs, *args, num_devices=1):
  """(sum over the batch of `sums`, max over the batch of `maxes`), where
  `fn(x, *args)` = (sums, maxes), two pytrees of numeric arrays; inside jit.

  With `num_devices` > 1 the batch is split over the first `num_devices` devices of
  `mesh_devices()` (args replicated); each device accumulates its elements one after
  another (`jax.lax.scan`: memory holds one element's result beside the running totals,
  whatever the batch), and the devices' totals are combined (`psum`, `pmax`) and
  replicated on every device (a batch of one element on one device is `fn` of it, with no
  loop around it: a data-parallel step with B = 1 is the plain step). The batch is padded
  to a multiple of `num_devices`; a padded slot is skipped (`lax.cond`), so it costs nothing
  and adds nothing.

  The sum is the same as a sequential one up to the order of the float additions: the
  devices' partial sums are added in the collective's order.

  Args:
    fn: `(one element of xs, *args)` -> (sums, maxes).
    xs: pytree whose leaves share a leading axis [B].
    *args: replicated arguments (pytrees).
    num_devices: devices to split the batch over (static).

  Returns:
    (sums, maxes) with fn's structure and shapes.
  """
  b = jax.tree.leaves(xs)[0].shape[0]
  if b == 1 and num_devices == 1:  # the sum and the max of one element: the element itself
    return fn(jax.tree.map(lambda x: x[0], xs), *args)
  total = num_devices * math.ceil(b / num_devices)
  xs = _pad(xs, total)
  real = jnp.arange(total) < b

  def local(batch, keep, *a):
    shapes = jax.eval_shape(fn, jax.tree.map(lambda x: x[0], batch), *a)
    # The identities: a padded slot adds zero to the sums and the lowest value to the maxes.
    sums0 = jax.tree.map(lambda t: jnp.zeros(t.shape, t.dtype), shapes[0])
    maxes0 = jax.tree.map(lambda t: _lowest(jnp.zeros(t.shape, t.dtype)), shapes[1])

    def one(x, real):
      return jax.lax.cond(real, lambda: fn(x, *a), lambda: (sums0, maxes0))

    def body(carry, item):
      sums, maxes = one(*item)
      carry = (jax.tree.map(jnp.add, carry[0], sums),
               jax.tree.map(jnp.maximum, carry[1], maxes))
      return carry, None

    (sums, maxes), _ = jax.lax.scan(body, (sums0, maxes0), (batch, keep))
    if num_devices > 1:
      sums = jax.lax.psum(sums, AXIS)
      maxes = jax.lax.pmax(maxes, AXIS)
    return sums, maxes

  if num_devices == 1:
    return local(xs, real, *args)
  mesh = batch_mesh(num_devices)
  specs = (PartitionSpec(AXIS), PartitionSpec(AXIS)) + (PartitionSpec(),) * len(args)
  out = jax.shard_map(local, mesh=mesh, in_specs=specs, out_specs=PartitionSpec(),
                      check_vma=False)(xs, real, *args)
  return _replicate_outputs(out, mesh)


def map_cameras(fn, cameras: Camera, *args, chunk_size=1, num_devices=1):
  """`map_sharded` over a `Camera` batched over one axis [B]: `fn(camera, *args)` each."""
  if len(cameras.batch_shape) != 1:
    raise ValueError(f"map_cameras takes a Camera batched over one axis, got "
                     f"{cameras.batch_shape}")
  return map_sharded(fn, cameras, *args, chunk_size=chunk_size, num_devices=num_devices)


def default_num_devices(num_items):
  """Devices to split `num_items` over: all of them (every process's) when there is more
  than one item, so that every split computation uses the same mesh (module docstring);
  a padded element costs nothing. One item: one device (each process computes it alone)."""
  return jax.device_count() if int(num_items) > 1 else 1
