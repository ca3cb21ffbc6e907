"""Constrained non-dominated sorting, crowding distance and survival (NSGA-II).

Implements the ranking machinery of NSGA-II (K. Deb, A. Pratap, S. Agarwal, T. Meyarivan,
"A fast and elitist multiobjective genetic algorithm: NSGA-II", IEEE Trans. Evol. Comput.
6(2):182-197, 2002, https://doi.org/10.1109/4235.996017) with Deb's constraint-domination,
as docs/conventions.md §6-7 requires of every optimiser:

- a feasible candidate (total violation 0) dominates every infeasible one;
- of two infeasible candidates the one with the smaller total violation dominates; equal
  violations dominate neither way;
- of two feasible candidates, Pareto dominance on the objectives (minimisation).

Every function is a pure ``jax.numpy`` array function: it jits, vmaps over a leading batch
axis, and has no Python loop over individuals or fronts. Precision follows the inputs
(float32 by default; float64 under ``with jax.enable_x64(True):``). Shapes below: ``n``
candidates, ``m`` objectives, ``c`` constraints.

Differences from pymoo 0.6.2 (the test-suite's reference), all deliberate:

- ``crowding_distance`` is Deb's sum over objectives (conventions §10); pymoo's
  ``calc_crowding_distance`` divides that sum by ``m``. The factor is uniform, so no comparison
  inside a front changes. Duplicates are not removed: within a front equal values are
  ordered by index, as pymoo 0.6.2's stable sort of ``"cd"`` does, so the two agree (up to
  the factor) on duplicates too; some older pymoo versions gave duplicates a distance of 0.
- Two infeasible candidates with equal total violation share a front here. pymoo's
  ``Dominator.get_relation`` falls back to Pareto dominance on the objectives in that case
  (and its survival sorts infeasible candidates by violation alone, breaking ties arbitrarily).
- Ties in ``survive`` are broken deterministically (lower index first); pymoo breaks crowding
  ties at random.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

__all__ = [
    "constrained_dominance",
    "crowding_distance",
    "nondominated_rank",
    "nondominated_rank_2d",
    "rank_and_crowding",
    "survive",
    "total_violation",
    "lexsort",
]


def total_violation(G: jax.Array) -> jax.Array:
    """Total constraint violation, the sum of the positive parts of the constraint values.

    Args:
        G: (n, c) constraint values; a candidate is feasible when all its values are <= 0.

    Returns:
        (n,) total violation, >= 0, and exactly 0 for feasible candidates.
    """
    G = jnp.asarray(G)
    return jnp.sum(jnp.maximum(G, 0), axis=-1)


def _sort_key(x: jax.Array) -> jax.Array:
    """int64 whose order is ``lax.sort``'s order of x: for floats, -0.0 equals +0.0 and
    every NaN is last (JAX canonicalises both before comparing), the rest by value."""
    if jnp.issubdtype(x.dtype, jnp.floating):
        x = jnp.where(x == 0, jnp.zeros_like(x), x)
        x = jnp.where(jnp.isnan(x), jnp.full_like(x, jnp.nan), x)
        itype = jnp.dtype(f"int{8 * x.dtype.itemsize}")
        b = lax.bitcast_convert_type(x, itype)
        # negative floats: larger magnitude, smaller number
        x = jnp.where(b < 0, b ^ jnp.array(jnp.iinfo(itype).max, itype), b)
    return x.astype(jnp.int64)


PACKED_MIN = 64
"""Members from which :func:`lexsort` packs its keys (below, JAX's sort is as cheap and
compiles smaller)."""


def lexsort(keys, packed: bool | None = None) -> jax.Array:
    """``jnp.lexsort(keys)`` (the last key primary, ties in index order), the same
    permutation, by one sort of packed integers.

    XLA:CPU sorts a single integer array with a plain comparison, but calls a compiled
    comparator for every comparison of a multi-key or floating-point sort, several times
    dearer for the few hundred members survival sorts. Each key is replaced by its ordinal (how many
    values sort strictly before it: a sort of the key alone and a binary search), and the
    ordinals and the index are packed into one int64. Falls back to ``jnp.lexsort`` when
    64-bit integers are off (JAX's default precision) or the packed key would not fit.

    Args:
        keys: sequence of (..., n) arrays (bool, integer or floating), as ``jnp.lexsort``.
        packed: force (True) or refuse (False) the packed sort; default: packed from
            :data:`PACKED_MIN` members.

    Returns:
        (..., n) int32 permutation.
    """
    keys = [jnp.asarray(k) for k in keys]
    if not keys or keys[0].ndim == 0:
        raise ValueError("lexsort needs at least one key of at least one dimension")
    if any(k.shape != keys[0].shape for k in keys):
        raise ValueError(f"lexsort keys must share one shape, got {[k.shape for k in keys]}")
    n = keys[0].shape[-1]
    bits = max(1, (n - 1).bit_length())
    packed = n >= PACKED_MIN if packed is None else packed
    if not packed or jax.dtypes.canonicalize_dtype(jnp.int64) != jnp.int64 or bits * (len(keys) + 1) > 63:
        return jnp.lexsort(keys).astype(jnp.int32)
    if keys[0].ndim > 1:  # one sort per leading index
        return jax.vmap(lambda *k: lexsort(k, packed=True))(*keys)
    word = jnp.zeros(keys[0].shape, jnp.int64)
    for k in keys[::-1]:  # primary key first, in the highest bits
        u = _sort_key(k)
        ordinal = jnp.searchsorted(lax.sort(u), u, side="left", method="scan")
        word = (word << bits) | ordinal.astype(jnp.int64)
    word = (word << bits) | jnp.arange(n, dtype=jnp.int64)
    return (lax.sort(word) & ((1 << bits) - 1)).astype(jnp.int32)


def _pareto_dominance(F: jax.Array) -> jax.Array:
    """(n, n) bool, [i, j] True iff F[i] <= F[j] in every objective and < in one."""
    a, b = F[:, None, :], F[None, :, :]
    return jnp.all(a <= b, axis=-1) & jnp.any(a < b, axis=-1)


def constrained_dominance(F: jax.Array, cv: jax.Array) -> jax.Array:
    """Deb's constraint-domination matrix.

    Args:
        F: (n, m) objective values, minimised.
        cv: (n,) total violation (see `total_violation`); feasible when <= 0.

    Returns:
        (n, n) bool, ``D[i, j]`` True iff candidate i constrained-dominates candidate j.
    """
    F, cv = jnp.asarray(F), jnp.asarray(cv)
    feasible = cv <= 0
    both_feasible = feasible[:, None] & feasible[None, :]
    smaller_cv = cv[:, None] < cv[None, :]
    return jnp.where(both_feasible, _pareto_dominance(F), smaller_cv)


def nondominated_rank(F: jax.Array, cv: jax.Array, stop_after: int | None = None) -> jax.Array:
    """0-based non-dominated front index under constrained dominance, any number of objectives.

    Peels fronts in a ``lax.while_loop``: a member not yet ranked joins the current front when
    no other unranked member dominates it. O(n^2 m) memory and O(n^2 (m + fronts)) work.
    Under ``vmap`` this is faster than the sort-based `nondominated_rank_2d` (whose scan over
    members is sequential) unless there are very many fronts.

    Args:
        F: (n, m) objective values, minimised.
        cv: (n,) total violation.
        stop_after: static; if given, stop peeling once at least this many members are
            ranked (survival needs no more): the members left share the next front index.

    Returns:
        (n,) int32 front index; 0 is the best front.
    """
    D = constrained_dominance(F, cv)
    n = F.shape[0]
    need = n if stop_after is None else min(int(stop_after), n)

    def cond(state: tuple[jax.Array, jax.Array]) -> jax.Array:
        rank, _ = state
        return jnp.sum(rank >= 0) < need

    def body(state: tuple[jax.Array, jax.Array]) -> tuple[jax.Array, jax.Array]:
        rank, front = state
        unranked = rank < 0
        dominated = jnp.any(D & unranked[:, None], axis=0)
        rank = jnp.where(unranked & ~dominated, front, rank)
        return rank, front + 1

    rank0 = jnp.full((n,), -1, dtype=jnp.int32)
    rank, front = lax.while_loop(cond, body, (rank0, jnp.int32(0)))
    return jnp.where(rank < 0, front, rank)


def nondominated_rank_2d(F: jax.Array, cv: jax.Array) -> jax.Array:
    """Same ranks as `nondominated_rank` for exactly two objectives, by sorting.

    Feasible members are visited in lexicographic order of (f1, f2), so every member's
    dominators come before it. Front k keeps its last member (the smallest f2 so far); a new
    member is dominated by front k iff that member's (f2, f1) is lexicographically smaller than
    its own, and the fronts that dominate it form a prefix, found by binary search. Work is
    O(n log n). Infeasible members follow the last feasible front, one front per distinct
    total violation in increasing order.

    Args:
        F: (n, 2) objective values, minimised.
        cv: (n,) total violation.

    Returns:
        (n,) int32 front index; 0 is the best front.
    """
    F, cv = jnp.asarray(F), jnp.asarray(cv)
    n = F.shape[0]
    if F.shape[1] != 2:
        raise ValueError(f"nondominated_rank_2d needs 2 objectives, got {F.shape[1]}")
    feasible = cv <= 0
    # Feasible first, each group in lexicographic (f1, f2) order; jnp.lexsort is stable.
    order = lexsort((F[:, 1], F[:, 0], ~feasible))
    f1, f2, feas_s = F[order, 0], F[order, 1], feasible[order]
    n_steps = max(1, n.bit_length())  # enough halvings for an interval of n + 1 fronts
    inf = jnp.array(jnp.inf, dtype=F.dtype)

    def visit(
        carry: tuple[jax.Array, jax.Array], x: tuple[jax.Array, jax.Array, jax.Array]
    ) -> tuple[tuple[jax.Array, jax.Array], jax.Array]:
        last1, last2 = carry
        a, b, feas = x

        def halve(_: int, lohi: tuple[jax.Array, jax.Array]) -> tuple[jax.Array, jax.Array]:
            lo, hi = lohi
            mid = (lo + hi) // 2
            dominated = (last2[mid] < b) | ((last2[mid] == b) & (last1[mid] < a))
            return jnp.where(dominated, mid + 1, lo), jnp.where(dominated, hi, mid)

        r, _ = lax.fori_loop(0, n_steps, halve, (jnp.int32(0), jnp.int32(n)))
        last1 = jnp.where(feas, last1.at[r].set(a), last1)
        last2 = jnp.where(feas, last2.at[r].set(b), last2)
        return (last1, last2), r

    # One spare slot so that the search interval [0, n] is always indexable.
    start = (jnp.full((n + 1,), inf), jnp.full((n + 1,), inf))
    _, r_sorted = lax.scan(visit, start, (f1, f2, feas_s))
    rank_feasible = jnp.zeros((n,), jnp.int32).at[order].set(r_sorted)
    n_fronts = jnp.max(jnp.where(feasible, rank_feasible + 1, 0))

    # Infeasible: dense rank of the violation among the infeasible members.
    cv_key = jnp.where(feasible, jnp.inf, cv)
    order_cv = lexsort((cv_key,))
    s = cv_key[order_cv]
    new_value = jnp.concatenate([jnp.zeros((1,), jnp.int32), (s[1:] != s[:-1]).astype(jnp.int32)])
    dense = jnp.zeros((n,), jnp.int32).at[order_cv].set(jnp.cumsum(new_value))
    return jnp.where(feasible, rank_feasible, n_fronts + dense).astype(jnp.int32)


def _neighbour_gap(f: jax.Array, rank: jax.Array) -> jax.Array:
    """Gap between each member's neighbours in its front along one objective.

    f: (n,), rank: (n,) -> (n,) ``f[next] - f[prev]`` in the front sorted by (f, index), +inf
    for the front's two ends.
    """
    n = f.shape[0]
    order = lexsort((f, rank))  # by front, then by value, then by index
    fs, rs = f[order], rank[order]
    same = rs[1:] == rs[:-1]
    inner = jnp.concatenate([jnp.zeros((1,), bool), same]) & jnp.concatenate(
        [same, jnp.zeros((1,), bool)]
    )
    pos = jnp.arange(n)
    gap = fs[jnp.minimum(pos + 1, n - 1)] - fs[jnp.maximum(pos - 1, 0)]
    gap = jnp.where(inner, gap, jnp.inf)
    return jnp.zeros_like(f).at[order].set(gap)


def crowding_distance(F: jax.Array, rank: jax.Array) -> jax.Array:
    """NSGA-II crowding distance within each front (members of equal rank).

    Per objective, a front's members are sorted by value (ties by index); the two ends get
    +inf and an inner member adds ``(f[i+1] - f[i-1]) / (f_max - f_min)`` of its front. An
    objective whose range in the front is 0 contributes nothing (not even the +inf of the
    ends). Members of fronts with at most two members get +inf. Unlike pymoo the sum is not
    divided by the number of objectives (see the module docstring).

    Args:
        F: (n, m) objective values.
        rank: (n,) integer front index of each member, in [0, n) (as `nondominated_rank`
            returns it).

    Returns:
        (n,) crowding distance, >= 0, possibly +inf; larger means less crowded.
    """
    F, rank = jnp.asarray(F), jnp.asarray(rank)
    n = F.shape[0]
    span = (
        jax.ops.segment_max(F, rank, num_segments=n) - jax.ops.segment_min(F, rank, num_segments=n)
    )[rank]  # (n, m): range of each objective in the member's front
    size = jax.ops.segment_sum(jnp.ones((n,), jnp.int32), rank, num_segments=n)[rank]
    gap = jax.vmap(_neighbour_gap, in_axes=(1, None), out_axes=1)(F, rank)
    has_span = span > 0
    cd = jnp.sum(jnp.where(has_span, gap / jnp.where(has_span, span, 1), 0), axis=1)
    return jnp.where(size <= 2, jnp.inf, cd).astype(F.dtype)


def rank_and_crowding(F: jax.Array, cv: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Constrained non-dominated rank and crowding distance.

    Uses `nondominated_rank_2d` when there are exactly two objectives (a static shape test),
    else `nondominated_rank`; both give identical ranks.

    Args:
        F: (n, m) objective values, minimised.
        cv: (n,) total violation.

    Returns:
        (n,) int32 rank and (n,) crowding distance.
    """
    F, cv = jnp.asarray(F), jnp.asarray(cv)
    if F.shape[1] == 2:
        rank = nondominated_rank_2d(F, cv)
    else:
        rank = nondominated_rank(F, cv)
    return rank, crowding_distance(F, rank)


def survive(F: jax.Array, cv: jax.Array, n_survive: int, return_rank: bool = False):
    """Indices of the best ``n_survive`` members by NSGA-II's crowded comparison.

    Order: lower constrained rank, then larger crowding distance, then lower index. Infeasible
    members are ranked after all feasible ones by total violation, so they enter in order of
    increasing violation. Fronts are peeled only until ``n_survive`` members are ranked
    (`nondominated_rank` with ``stop_after``); the survivors' ranks are their ranks in the
    whole set (removing worse members changes no better member's rank).

    Args:
        F: (n, m) objective values, minimised.
        cv: (n,) total violation.
        n_survive: static number of survivors, 0 <= n_survive <= n.
        return_rank: also return the survivors' front indices.

    Returns:
        (n_survive,) int32 indices into the n members, best first (and their (n_survive,)
        int32 ranks with ``return_rank``).
    """
    F, cv = jnp.asarray(F), jnp.asarray(cv)
    rank = nondominated_rank(F, cv, stop_after=n_survive)
    cd = crowding_distance(F, rank)
    order = lexsort((-cd, rank))[:n_survive]  # ties by index
    return (order, rank[order]) if return_rank else order
