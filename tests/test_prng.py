"""dockjax's keys (:mod:`dockjax.prng`) against JAX's default Threefry keys: every draw the
optimisers make must be bit-identical, jitted or not, vmapped or not, in float32 and in
float64 (JAX's own implementation is the reference)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dockjax import prng

DRAWS = {
    "bits32": lambda k: jax.random.bits(k, (7, 5)),
    "bits8": lambda k: jax.random.bits(k, (9,), jnp.uint8),
    "bits16": lambda k: jax.random.bits(k, (3,), jnp.uint16),
    "uniform": lambda k: jax.random.uniform(k, (150, 36)),
    "normal": lambda k: jax.random.normal(k, (11, 3)),
    "scalar": lambda k: jax.random.uniform(k),
    "permutation": lambda k: jax.random.permutation(k, 150),
    "randint": lambda k: jax.random.randint(k, (150,), 0, 37),
    "bernoulli": lambda k: jax.random.bernoulli(k, 0.3, (20,)),
    "split": lambda k: jax.random.key_data(jax.random.split(k, 4)),
    "split_2d": lambda k: jax.random.key_data(jax.random.split(k, (2, 3))),
    "fold_in": lambda k: jax.random.key_data(jax.random.fold_in(k, 77)),
    "chain": lambda k: jax.random.normal(jax.random.split(jax.random.fold_in(k, 3), 3)[2], (5,)),
}


_ALL = jax.jit(lambda k: {name: draw(k) for name, draw in DRAWS.items()})


@pytest.mark.parametrize("x64", [False, True])
def test_draws_equal_jax_default_keys(x64):
    """Every draw of :data:`DRAWS` (one compiled program per key type), for four seeds."""
    with jax.enable_x64(x64):
        for seed in (0, 1, 12345, 2**31 - 1):
            ref, ours = jax.random.key(seed), prng.key(seed)
            assert jax.random.key_impl(ours) != jax.random.key_impl(ref)  # really the other implementation
            np.testing.assert_array_equal(jax.random.key_data(ours), jax.random.key_data(ref))
            want, got = _ALL(ref), _ALL(ours)
            for name in DRAWS:
                np.testing.assert_array_equal(np.asarray(got[name]), np.asarray(want[name]), err_msg=name)
        if x64:
            np.testing.assert_array_equal(np.asarray(jax.random.bits(ours, (3, 4), jnp.uint64)),
                                          np.asarray(jax.random.bits(ref, (3, 4), jnp.uint64)))
        # and op by op, outside jit
        np.testing.assert_array_equal(np.asarray(jax.random.uniform(ours, (5, 3))),
                                      np.asarray(jax.random.uniform(ref, (5, 3))))


def test_vmapped_draws_equal_single_and_default_keys():
    with jax.enable_x64(True):
        seeds = jnp.arange(5)
        ref, ours = jax.vmap(jax.random.key)(seeds), jax.vmap(prng.key)(seeds)
        draw = jax.vmap(lambda k: jax.random.uniform(k, (6, 4)))
        batch = np.asarray(draw(ours))
        np.testing.assert_array_equal(batch, np.asarray(draw(ref)))
        np.testing.assert_array_equal(batch[3], np.asarray(jax.random.uniform(prng.key(3), (6, 4))))
        split = jax.vmap(lambda k: jax.random.key_data(jax.random.split(k, 3)))
        np.testing.assert_array_equal(np.asarray(split(ours)), np.asarray(split(ref)))


def test_hash_matches_the_threefry_primitive():
    """The unrolled hash against JAX's ``threefry_2x32`` on arbitrary words (including the
    all-ones key and counters, where every addition wraps)."""
    from jax.extend.random import threefry_2x32

    rng = np.random.default_rng(0)
    words = rng.integers(0, 2**32, size=(4, 64), dtype=np.uint64).astype(np.uint32)
    words[:, 0] = np.uint32(0xFFFFFFFF)
    for k1, k2 in ((words[0, 0], words[1, 0]), (words[0, 5], words[1, 9])):
        a, b = prng.threefry2x32(jnp.uint32(k1), jnp.uint32(k2), jnp.asarray(words[2]), jnp.asarray(words[3]))
        ref = threefry_2x32((jnp.uint32(k1), jnp.uint32(k2)), jnp.concatenate([words[2], words[3]]))
        np.testing.assert_array_equal(np.concatenate([np.asarray(a), np.asarray(b)]), np.asarray(ref))


def test_partitionable_layout_or_jax_own():
    """With ``jax_threefry_partitionable`` switched off JAX draws another stream; the keys
    then hand every call to JAX's implementation and still agree with the default keys."""
    old = jax.config.jax_threefry_partitionable
    try:
        jax.config.update("jax_threefry_partitionable", False)
        for name in ("uniform", "split", "fold_in", "randint"):
            draw = DRAWS[name]
            np.testing.assert_array_equal(np.asarray(draw(prng.key(4))), np.asarray(draw(jax.random.key(4))),
                                          err_msg=name)
    finally:
        jax.config.update("jax_threefry_partitionable", old)


def test_draws_of_2_32_numbers_or_more_go_to_jax():
    """A draw of 2**32 numbers needs the counters' high words: JAX's implementation takes it
    (traced only, nothing is allocated)."""
    out = jax.eval_shape(lambda k: jax.random.bits(k, (2**16, 2**16)), prng.key(0))
    assert out.shape == (2**16, 2**16) and out.dtype == jnp.uint32
