"""Spreading independent work — optimisation runs, candidates to score — over JAX's devices.

Every device gets its share through ``jax.shard_map`` and runs its own program
(:func:`sharded`), with no communication. The one exception is a batch with fewer runs than
devices (one run, as ``dockjax plan`` makes): then every device runs the whole batch
(:func:`replicated`) except its dear part, the scoring of the candidates, whose rows each
device computes for its share and gathers from the others (:func:`share_rows`, one
explicit ``all_gather`` per evaluation). XLA:CPU's *automatic* partitioning is avoided: it
turned a vmapped while loop's batched condition into a cross-device all-reduce, and a
trial deadlocked in the rendezvous.

A CPU process has one device unless it asks for more *before* its first JAX computation:
``jax.config.update("jax_num_cpu_devices", n)`` (:func:`dockjax.cli.use_cpu_devices`).
"""

from __future__ import annotations

from functools import partial
from typing import Callable

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from . import checks

__all__ = ["AXIS", "SHARDED", "SAME", "choose", "mesh", "put", "sharded", "replicated", "share_rows"]

AXIS = "items"
"""The one mesh axis: runs of a batch, or rows of a population."""
SHARDED = PartitionSpec(AXIS)
"""Split along the leading axis."""
SAME = PartitionSpec()
"""The whole value on every device."""


def choose(devices: int | None, n_items: int) -> list:
    """The first ``devices`` of ``jax.local_devices()`` (None: all), at most one per item.

    Raises ValueError for anything but an integer from 1 to the number of local devices."""
    local = jax.local_devices()
    if devices is None:
        devices = len(local)
    elif not (checks.is_integer(devices) and 1 <= devices <= len(local)):
        raise ValueError(
            f"devices must be an integer from 1 to {len(local)} (JAX's local devices; a CPU "
            f"process gets more with jax.config.update('jax_num_cpu_devices', n) before its "
            f"first computation), got {devices!r}")
    return local[: max(1, min(int(devices), n_items))]


def mesh(devs: list) -> Mesh | None:
    """A one-axis mesh over ``devs``, or None for a single device (no sharding)."""
    return Mesh(np.asarray(devs), (AXIS,)) if len(devs) > 1 else None


def put(tree, where: Mesh | None):
    """Place a pytree split along its leading axis over the mesh (None: unchanged)."""
    return tree if where is None else jax.device_put(tree, NamedSharding(where, SHARDED))


@partial(jax.jit, static_argnames=("fn", "static", "where", "specs"))
def _sharded(fn: Callable, static: tuple, where: Mesh, specs: tuple, *args):
    body = partial(fn, *static)
    return jax.shard_map(body, mesh=where, in_specs=specs, out_specs=SHARDED, check_vma=False)(*args)


def sharded(fn: Callable, static: tuple, where: Mesh | None, specs: tuple, *args):
    """``fn(*static, *args)``, each device of ``where`` computing it for its share.

    ``specs``: one of :data:`SHARDED` (split along the leading axis, whose length the
    caller makes a multiple of the device count) or :data:`SAME` per element of ``args``;
    every output is split along its leading axis. ``fn`` and ``static`` must be hashable
    (a module-level function and, e.g., an algorithm module): the program is compiled once
    per (fn, static, mesh, shapes). ``where=None`` calls ``fn`` directly.
    """
    if where is None:
        return fn(*static, *args)
    return _sharded(fn, static, where, specs, *args)


@partial(jax.jit, static_argnames=("fn", "static", "where"))
def _replicated(fn: Callable, static: tuple, where: Mesh, *args):
    body = partial(fn, *static)
    return jax.shard_map(body, mesh=where, in_specs=SAME, out_specs=SAME, check_vma=False)(*args)


def replicated(fn: Callable, static: tuple, where: Mesh | None, *args):
    """``fn(*static, *args)`` computed whole by every device of ``where``, for a program
    that shares out its own dear part with :func:`share_rows` (every input and output is
    the whole value on every device; the devices compute the same outputs, so any copy is
    the result). Hashable ``fn`` and ``static`` as for :func:`sharded`; ``where=None``
    calls ``fn`` directly."""
    if where is None:
        return fn(*static, *args)
    return _replicated(fn, static, where, *args)


def share_rows(fn: Callable, parts: int, X, axis: int = 0):
    """Inside :func:`replicated` over ``parts`` devices: ``fn(X)`` with each device
    computing ``fn`` on its share of the rows of X along ``axis`` (the last share padded
    with copies of the last row) and every device getting all results, gathered in row
    order along the same axis. ``fn`` must be row-wise — a row's result may not depend on
    the other rows — and then the result equals ``fn(X)`` on one device."""
    n = X.shape[axis]
    m = -(-n // parts)
    if m * parts != n:
        last = jax.lax.slice_in_dim(X, n - 1, n, axis=axis)
        X = jax.numpy.concatenate([X] + [last] * (m * parts - n), axis=axis)
    mine = jax.lax.dynamic_slice_in_dim(X, jax.lax.axis_index(AXIS) * m, m, axis=axis)
    leaves, tree = jax.tree_util.tree_flatten(fn(mine))
    # the results of one dtype travel together: each all_gather is a rendezvous of the
    # devices (one IMOCS run on two devices took 0.89x the time with F, G and cv
    # gathered at once rather than one by one)
    out = [None] * len(leaves)
    for dtype in dict.fromkeys(a.dtype for a in leaves):
        idx = [i for i, a in enumerate(leaves) if a.dtype == dtype]
        rows = [jax.numpy.moveaxis(leaves[i], axis, 0) for i in idx]  # (m, ...) each
        flat = jax.numpy.concatenate([r.reshape(m, -1) for r in rows], axis=1)
        whole = jax.lax.all_gather(flat, AXIS, axis=0, tiled=True)[:n]
        start = 0
        for i, r in zip(idx, rows):
            width = r[0].size
            piece = whole[:, start:start + width].reshape((n,) + r.shape[1:])
            out[i] = jax.numpy.moveaxis(piece, 0, axis)
            start += width
    return jax.tree_util.tree_unflatten(tree, out)
