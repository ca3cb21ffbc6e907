"""Cuckoo-search operators shared by MOCS and IMOCS (paper §4.2–4.3, conventions §10).

* Lévy steps by Mantegna's method (Mantegna 1994; Yang & Deb 2013), β = 1.5.
* Discovery of alien eggs with probability ``p_a`` per component (conventions §7).
* The Bernoulli chaotic map (paper Eq. 31) and the chaotic initial population (Eq. 32),
  guarded against the finite-precision collapse of the map (conventions §7).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from ..fusion import materialize

__all__ = [
    "mantegna_sigma",
    "levy_step",
    "random_rank1_partner",
    "discovery",
    "bernoulli_map",
    "bernoulli_population",
]

LEVY_BETA = 1.5


def mantegna_sigma(beta: float = LEVY_BETA) -> float:
    """``σ_u = [Γ(1+β) sin(πβ/2) / (Γ((1+β)/2) β 2^((β−1)/2))]^(1/β)`` (≈ 0.6966 at β = 1.5).

    Note the exponent ``1/β`` (a version in circulation uses ``1/(2β)``; conventions §10).
    """
    num = math.gamma(1 + beta) * math.sin(math.pi * beta / 2)
    den = math.gamma((1 + beta) / 2) * beta * 2 ** ((beta - 1) / 2)
    return (num / den) ** (1 / beta)


def levy_step(key, shape, dtype, beta: float = LEVY_BETA):
    """Mantegna Lévy step ``u / |v|^(1/β)``, ``u ~ N(0, σ_u²)``, ``v ~ N(0, 1)`` per component."""
    ku, kv = jax.random.split(key)
    u = mantegna_sigma(beta) * jax.random.normal(ku, shape, dtype)
    v = jax.random.normal(kv, shape, dtype)
    return u / jnp.abs(v) ** (1.0 / beta)


def random_rank1_partner(key, rank):
    """For each nest, the index of a member drawn uniformly from the rank-1 set (conventions §7:
    ``x_j`` at random from the current non-dominated set). rank: (n,) → (n,) int32."""
    n = rank.shape[0]
    count = jnp.cumsum(rank == 0)  # count[i]: rank-1 members among 0..i
    j = jax.random.randint(key, (n,), 0, jnp.maximum(count[-1], 1))  # which rank-1 member
    return jnp.searchsorted(count, j, side="right").astype(jnp.int32)  # its index


def discovery(key, U, p_a):
    """Alien-egg discovery (Yang & Deb 2013; conventions §7): each component changes with
    probability ``p_a`` by ``r (x_a − x_b)``, a, b random permutations, ``r ~ U(0, 1)`` per
    component (the ``⊙`` of conventions §10). U: (n, d) → (n, d)."""
    U = materialize(U)  # read at permuted rows below
    n, d = U.shape
    k1, k2, k3, k4 = jax.random.split(key, 4)
    mask = jax.random.uniform(k1, (n, d), U.dtype) < p_a
    a = jax.random.permutation(k2, n)
    b = jax.random.permutation(k3, n)
    r = jax.random.uniform(k4, (n, d), U.dtype)
    return U + jnp.where(mask, r * (U[a] - U[b]), 0.0)


def bernoulli_map(z, rho):
    """Bernoulli map (paper Eq. 31): ``z/(1−ρ)`` if ``z <= 1−ρ``, else ``(z − (1−ρ))/ρ``."""
    return jnp.where(z <= 1.0 - rho, z / (1.0 - rho), (z - (1.0 - rho)) / rho)


GUARD = 1e-10
"""A chaotic value closer than this to 0, 1 − ρ or 1 is re-seeded."""
MEMORY = 8
"""A value equal to one of the last ``MEMORY`` values of its sequence (a cycle) is re-seeded."""


def bernoulli_population(key, n: int, d: int, rho, dtype=jnp.float64):
    """Chaotic initial nests in the unit box (paper Eqs. 31–32; conventions §7). → (n, d).

    One independent sequence per dimension: a random start, then ``n − 1`` iterations of the
    map. In binary floating point the map collapses (at ρ = 0.5 it is the doubling map and
    reaches the fixed point 0 in ~50 steps in float64; at ρ = 0.4 short cycles appear), so a
    value that comes within ``GUARD`` of 0, 1 − ρ or 1, or repeats one of the last
    ``MEMORY`` values of its sequence, is replaced by a fresh uniform draw from the key.
    Call under ``jax.enable_x64(True)`` for the float64 the paper's map needs.
    """
    rho = jnp.asarray(rho, dtype)
    lo, hi = 0.05, 0.95

    def fresh(k):
        return jax.random.uniform(k, (d,), dtype, lo, hi)

    k0, kseq = jax.random.split(key)
    z0 = fresh(k0)

    def body(carry, k):
        z, memory = carry
        nz = bernoulli_map(z, rho)
        bad = (nz < GUARD) | (nz > 1.0 - GUARD) | (jnp.abs(nz - (1.0 - rho)) < GUARD)
        bad = bad | jnp.any(jnp.abs(memory - nz[None, :]) == 0.0, axis=0)
        nz = jnp.where(bad, fresh(k), nz)
        memory = jnp.concatenate([memory[1:], nz[None, :]], axis=0)
        return (nz, memory), nz

    memory = jnp.full((MEMORY, d), -1.0, dtype).at[-1].set(z0)
    _, rest = jax.lax.scan(body, (z0, memory), jax.random.split(kseq, n - 1))
    return jnp.concatenate([z0[None, :], rest], axis=0)
