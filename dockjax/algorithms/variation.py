"""Genetic variation operators of NSGA-II in the unit box (conventions §10; pymoo's defaults).

* Bounded simulated binary crossover, SBX (K. Deb and R. B. Agrawal, "Simulated binary
  crossover for continuous search space", Complex Systems 9(2):115–148, 1995), in the
  bounded form of Deb's NSGA-II code and pymoo's ``cross_sbx``.
* Polynomial mutation (K. Deb and M. Goyal, "A combined genetic adaptive search (GeneAS)
  for engineering design", Computer Science and Informatics 26(4):30–45, 1996), in the
  bounded form of the same codes.
* Binary tournament on Deb's constraint-domination, then rank, then crowding distance
  (K. Deb, A. Pratap, S. Agarwal and T. Meyarivan, "A fast and elitist multiobjective
  genetic algorithm: NSGA-II", IEEE Trans. Evol. Comput. 6(2):182–197, 2002,
  https://doi.org/10.1109/4235.996017; the constraint rule is K. Deb, "An efficient
  constraint handling method for genetic algorithms", Comput. Methods Appl. Mech. Engrg.
  186:311–338, 2000).

All three are pure ``jax.numpy`` functions with explicit keys: they jit and vmap, and their
hyper-parameters may be traced (so a batch of runs can vary them). Every search space here
is the unit box, so ``xl = 0`` and ``xu = 1`` throughout.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["sbx", "polynomial_mutation", "binary_tournament", "SBX_EPS"]

SBX_EPS = 1e-14
"""Variables whose parent values differ by at most this are not crossed (pymoo's ``eps``)."""


def sbx(
    key: jax.Array,
    parents_a: jax.Array,
    parents_b: jax.Array,
    eta=15.0,
    prob=0.9,
    prob_var=0.5,
) -> tuple[jax.Array, jax.Array]:
    """Bounded simulated binary crossover (Deb & Agrawal 1995) of parent pairs in [0, 1].

    A pair is crossed with probability ``prob``; in a crossed pair each variable is crossed
    with probability ``prob_var`` unless its two values differ by at most ``SBX_EPS``. For a
    crossed variable with ``y1 < y2``, ``Δ = y2 − y1`` and one ``u ~ U(0, 1)``::

        β = 1 + 2 (y1 − xl)/Δ,  α = 2 − β^−(η+1),
        β_q = (u α)^(1/(η+1))  if u ≤ 1/α  else  (1/(2 − u α))^(1/(η+1)),
        c1 = ½ [(y1 + y2) − β_q Δ];   c2 likewise with β = 1 + 2 (xu − y2)/Δ and ``+``,

    and the two children are swapped with probability ½. Far from the bounds (β → ∞,
    α → 2) both β_q coincide and the children's mean equals the parents'. Children are
    clipped to [0, 1] (a no-op up to rounding: the bounded form stays inside).

    Args:
        key: PRNG key.
        parents_a, parents_b: (p, d) the pairs' first and second parents, in [0, 1].
        eta: distribution index η_c > 0 (larger: children closer to the parents).
        prob: probability that a pair is crossed at all.
        prob_var: probability that a variable of a crossed pair is crossed.

    Returns:
        (child_a, child_b), each (p, d); uncrossed variables copy ``parents_a``/``parents_b``.
    """
    a = jnp.asarray(parents_a)
    b = jnp.asarray(parents_b)
    p, d = a.shape
    dtype = a.dtype
    k_pair, k_var, k_u, k_swap = jax.random.split(key, 4)
    cross = (
        (jax.random.uniform(k_pair, (p, 1), dtype) < prob)
        & (jax.random.uniform(k_var, (p, d), dtype) < prob_var)
        & (jnp.abs(a - b) > SBX_EPS)
    )
    y1 = jnp.minimum(a, b)
    y2 = jnp.maximum(a, b)
    delta = jnp.where(cross, y2 - y1, 1.0)  # 1.0 keeps the unused lanes finite
    u = jax.random.uniform(k_u, (p, d), dtype)
    expo = 1.0 / (eta + 1.0)

    def beta_q(beta):
        alpha = 2.0 - beta ** (-(eta + 1.0))
        return jnp.where(u <= 1.0 / alpha, (u * alpha) ** expo, (1.0 / (2.0 - u * alpha)) ** expo)

    c1 = 0.5 * ((y1 + y2) - beta_q(1.0 + 2.0 * y1 / delta) * delta)
    c2 = 0.5 * ((y1 + y2) + beta_q(1.0 + 2.0 * (1.0 - y2) / delta) * delta)
    swap = jax.random.uniform(k_swap, (p, d), dtype) < 0.5
    child_a = jnp.where(cross, jnp.where(swap, c2, c1), a)
    child_b = jnp.where(cross, jnp.where(swap, c1, c2), b)
    return jnp.clip(child_a, 0.0, 1.0), jnp.clip(child_b, 0.0, 1.0)


def polynomial_mutation(key: jax.Array, X: jax.Array, eta=20.0, prob_var=None) -> jax.Array:
    """Bounded polynomial mutation (Deb & Goyal 1996) in [0, 1].

    Each variable mutates with probability ``prob_var`` (default ``1/d``, about one variable
    per individual). With ``δ1 = x − xl``, ``δ2 = xu − x`` (unit box) and ``r ~ U(0, 1)``::

        δ_q = [2r + (1 − 2r)(1 − δ1)^(η+1)]^(1/(η+1)) − 1           if r ≤ ½,
        δ_q = 1 − [2(1 − r) + 2(r − ½)(1 − δ2)^(η+1)]^(1/(η+1))     otherwise,

    ``x' = x + δ_q``, then clipped to [0, 1] against rounding.

    Args:
        key: PRNG key.
        X: (n, d) candidates in [0, 1].
        eta: distribution index η_m > 0.
        prob_var: per-variable mutation probability; None for ``1/d``.

    Returns:
        (n, d) mutated candidates.
    """
    X = jnp.asarray(X)
    n, d = X.shape
    if prob_var is None:
        prob_var = 1.0 / d
    k_mask, k_r = jax.random.split(key)
    mutate = jax.random.uniform(k_mask, (n, d), X.dtype) < prob_var
    r = jax.random.uniform(k_r, (n, d), X.dtype)
    expo = 1.0 / (eta + 1.0)
    # Both branches are finite for every r in [0, 1): each base is >= 1 off its own branch.
    low = (2.0 * r + (1.0 - 2.0 * r) * (1.0 - X) ** (eta + 1.0)) ** expo - 1.0
    high = 1.0 - (2.0 * (1.0 - r) + 2.0 * (r - 0.5) * X ** (eta + 1.0)) ** expo
    delta_q = jnp.where(r <= 0.5, low, high)
    return jnp.clip(jnp.where(mutate, X + delta_q, X), 0.0, 1.0)


def binary_tournament(
    key: jax.Array, rank: jax.Array, crowding: jax.Array, cv: jax.Array, n: int
) -> jax.Array:
    """Deb's constrained binary tournament (Deb 2000; Deb et al. 2002). → (n,) int32 indices.

    Contestants come from concatenated random permutations of the population (as in Deb's
    code and pymoo), so each member enters about ``2n/N`` tournaments. The winner of a pair:
    if either is infeasible (``cv > 0``), the smaller total violation; if both are feasible,
    the lower non-dominated rank, then the larger crowding distance; a remaining tie is
    decided by a fair coin.

    Args:
        key: PRNG key.
        rank: (N,) non-dominated front index (0 best).
        crowding: (N,) crowding distance (larger is better; may be +inf).
        cv: (N,) total constraint violation (0 when feasible).
        n: static number of tournaments (winners).

    Returns:
        (n,) int32 indices of the winners, in [0, N).
    """
    N = rank.shape[0]
    k_perm, k_coin = jax.random.split(key)
    n_perm = -(-2 * n // N)  # ceil(2n / N)
    perms = jax.vmap(lambda k: jax.random.permutation(k, N))(jax.random.split(k_perm, n_perm))
    pairs = perms.reshape(-1)[: 2 * n].reshape(n, 2)
    i, j = pairs[:, 0], pairs[:, 1]
    infeasible = (cv[i] > 0) | (cv[j] > 0)
    i_better = jnp.where(
        infeasible,
        cv[i] < cv[j],
        (rank[i] < rank[j]) | ((rank[i] == rank[j]) & (crowding[i] > crowding[j])),
    )
    j_better = jnp.where(
        infeasible,
        cv[j] < cv[i],
        (rank[j] < rank[i]) | ((rank[i] == rank[j]) & (crowding[j] > crowding[i])),
    )
    coin = jax.random.bernoulli(k_coin, 0.5, (n,))
    take_i = i_better | (~j_better & coin)
    return jnp.where(take_i, i, j).astype(jnp.int32)
