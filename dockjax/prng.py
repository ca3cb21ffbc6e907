"""JAX's Threefry-2x32 random numbers, bit for bit, as straight-line code on the CPU.

Every random choice of dockjax flows from a JAX key (``jax.random.key(seed)``, Threefry
2x32). On the CPU JAX lowers the Threefry hash as a rolled loop of five trips (to keep
compile times short), and XLA:CPU runs each trip as a handful of small kernels. A
cuckoo-search iteration draws a few thousand numbers at a time, and there the loop's
overhead is most of the cost of a draw.

:data:`IMPL` is the same generator — same seeding, splitting, folding and bits, so every
draw is identical to JAX's default keys' (a test compares them) — with the hash written out
as its 20 rounds, which XLA fuses into one kernel per draw (its result materialised, see
:func:`threefry2x32`). Keys made with :func:`key` carry it; ``jax.random.uniform``,
``normal``, ``split``, … then use it through JAX's public extension point
(:func:`jax.extend.random.define_prng_impl`). Nothing global changes: other keys keep
JAX's own lowering.

The straight-line form follows JAX's ``threefry_partitionable`` layout (the default since
JAX 0.5): the counter of element i of a draw is i itself, as a 64-bit number split in two
32-bit words. If a process switches that flag off, or a single draw holds 2**32 numbers
or more, :data:`IMPL` hands the call to JAX's own implementation, so draws still equal the
default keys'.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.extend.random import define_prng_impl, threefry_prng_impl

from .fusion import materialize

__all__ = ["IMPL", "key", "threefry2x32"]

_ROTATIONS = ((13, 15, 26, 6), (17, 29, 16, 24))
_PARITY = np.uint32(0x1BD11BDA)


def _rotate_left(x, r: int):
    return (x << np.uint32(r)) | (x >> np.uint32(32 - r))


def threefry2x32(k1, k2, x1, x2):
    """The Threefry-2x32 hash (Salmon et al., SC'11: 20 rounds, key injection every 4) of
    the counter words ``(x1, x2)`` under the key ``(k1, k2)``; uint32 arrays, broadcast.
    → the two hashed words. The same arithmetic as JAX's lowering, unrolled."""
    ks = (k1, k2, k1 ^ k2 ^ _PARITY)
    x1, x2 = x1 + ks[0], x2 + ks[1]
    for i in range(5):
        for r in _ROTATIONS[i % 2]:
            x1 = x1 + x2
            x2 = _rotate_left(x2, r) ^ x1
        x1 = x1 + ks[(i + 1) % 3]
        x2 = x2 + ks[(i + 2) % 3] + np.uint32(i + 1)
    # computed once into buffers: XLA:CPU otherwise fused the whole hash into each of its
    # consumers (the bits of a draw are read several times); the cuckoo loop then compiled
    # so slowly that XLA's slow-compile alarm fired, and drew slower than JAX's own loop
    return materialize((x1, x2))


def _counters(shape):
    """The partitionable counters of a draw of ``shape`` (fewer than 2**32 numbers, see
    :func:`_straight`): element i (row-major) gets the 64-bit number i, as (high, low)
    uint32 words; the high word is 0."""
    lo = jnp.zeros(shape, jnp.uint32)
    stride = 1
    for axis in range(len(shape) - 1, -1, -1):
        lo = lo + jax.lax.broadcasted_iota(jnp.uint32, shape, axis) * np.uint32(stride)
        stride *= shape[axis]
    return jnp.zeros(shape, jnp.uint32), lo


def _straight(shape) -> bool:
    """Whether a draw of ``shape`` takes the straight-line hash: JAX's partitionable layout
    is on, and the counters fit in their low words. Otherwise JAX's implementation draws
    (the same numbers)."""
    return bool(jax.config.jax_threefry_partitionable) and math.prod(shape) < 2**32


def _random_bits(key_data, bit_width, shape):
    if not _straight(shape):
        return threefry_prng_impl.random_bits(key_data, bit_width, shape)
    if bit_width not in (8, 16, 32, 64):
        raise TypeError(f"random bits must be 8, 16, 32 or 64 wide, got {bit_width}")
    b1, b2 = threefry2x32(key_data[0], key_data[1], *_counters(tuple(shape)))
    if bit_width == 64:
        return (b1.astype(jnp.uint64) << np.uint64(32)) | b2.astype(jnp.uint64)
    bits = b1 ^ b2
    return bits if bit_width == 32 else bits.astype(jnp.dtype(f"uint{bit_width}"))


def _split(key_data, shape):
    if not _straight(shape):
        return threefry_prng_impl.split(key_data, shape)
    b1, b2 = threefry2x32(key_data[0], key_data[1], *_counters(tuple(shape)))
    return jnp.stack([b1, b2], axis=-1)


def _fold_in(key_data, data):
    if not _straight(()):
        return threefry_prng_impl.fold_in(key_data, data)
    # JAX hashes the seed words of ``data`` as one counter pair
    seed = threefry_prng_impl.seed(jnp.asarray(data, jnp.uint32))
    b1, b2 = threefry2x32(key_data[0], key_data[1], seed[:1], seed[1:])
    return jnp.concatenate([b1, b2])


IMPL = define_prng_impl(
    key_shape=threefry_prng_impl.key_shape,
    seed=threefry_prng_impl.seed,
    split=_split,
    random_bits=_random_bits,
    fold_in=_fold_in,
    name="threefry2x32_unrolled",
    tag="fryu",
)
"""JAX's Threefry-2x32 with the hash unrolled (see the module docstring)."""


def key(seed) -> jax.Array:
    """``jax.random.key(seed)`` with :data:`IMPL`: the same numbers as JAX's default key of
    that seed, drawn faster on the CPU."""
    return jax.random.key(seed, impl=IMPL)
