"""Tests of dockjax.pareto against pymoo 0.6.2 as the independent reference.

pymoo's pieces used: ``NonDominatedSorting`` (ranks of feasible sets), ``Dominator``
(constrained dominance between two candidates), the ``"cd"`` crowding function and the
``RankAndCrowding`` survival of NSGA-II. Where our documented rule differs from pymoo (equal
violations of infeasible candidates, the 1/m factor of the crowding distance), the test says so.
"""

from __future__ import annotations

import functools

import hypothesis.extra.numpy as hnp
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from pymoo.core.population import Population
from pymoo.core.problem import Problem
from pymoo.operators.survival.rank_and_crowding import RankAndCrowding
from pymoo.operators.survival.rank_and_crowding.metrics import get_crowding_function
from pymoo.util.dominator import Dominator
from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

from dockjax import pareto

# A few population sizes only, so that jit compiles a handful of shapes.
SIZES = (1, 3, 16, 32)

rank_general = jax.jit(pareto.nondominated_rank)
rank_2d = jax.jit(pareto.nondominated_rank_2d)
crowding = jax.jit(pareto.crowding_distance)
dominance = jax.jit(pareto.constrained_dominance)
rank_and_crowding = jax.jit(pareto.rank_and_crowding)
total_violation = jax.jit(pareto.total_violation)


@functools.partial(jax.jit, static_argnums=2)
def survive(F, cv, n_survive):
    return pareto.survive(F, cv, n_survive)


# ----------------------------------------------------------------------------- references
def pymoo_ranks(F: np.ndarray) -> np.ndarray:
    """Unconstrained ranks by pymoo's NonDominatedSorting."""
    _, rank = NonDominatedSorting().do(np.asarray(F, float), return_rank=True)
    return rank


def peel(relation) -> np.ndarray:
    """Fronts from an explicit (n, n) dominance matrix, O(n^2) per front, plain numpy."""
    D = np.asarray(relation, bool)
    n = D.shape[0]
    rank = np.full(n, -1)
    k = 0
    while (rank < 0).any():
        unranked = rank < 0
        front = unranked & ~(D & unranked[:, None]).any(axis=0)
        assert front.any(), "dominance relation has a cycle"
        rank[front] = k
        k += 1
    return rank


def pymoo_dominance(F: np.ndarray, cv: np.ndarray) -> np.ndarray:
    """D[i, j] = pymoo's Dominator says i dominates j."""
    n = len(F)
    return np.array(
        [
            [Dominator.get_relation(F[i], F[j], cv[i], cv[j]) == 1 for j in range(n)]
            for i in range(n)
        ]
    )


def documented_dominance(F: np.ndarray, cv: np.ndarray) -> np.ndarray:
    """Our documented rule, written out case by case (equal violations: neither dominates)."""
    n = len(F)
    D = np.zeros((n, n), bool)
    for i in range(n):
        for j in range(n):
            if cv[i] == 0 and cv[j] == 0:
                D[i, j] = np.all(F[i] <= F[j]) and np.any(F[i] < F[j])
            else:
                D[i, j] = cv[i] < cv[j]
    return D


# ----------------------------------------------------------------------------- strategies
@st.composite
def populations(draw, m=None, integer=None, infeasible=True, distinct_cv=False):
    """(F, cv): integer-valued F with many ties and duplicates, or floats; cv >= 0."""
    n = draw(st.sampled_from(SIZES))
    m = draw(st.sampled_from((2, 3))) if m is None else m
    integer = draw(st.booleans()) if integer is None else integer
    if integer:
        F = draw(hnp.arrays(np.int64, (n, m), elements=st.integers(0, 3))).astype(float)
    else:
        F = draw(hnp.arrays(np.float64, (n, m), elements=st.floats(-1, 1, width=32)))
    cv = np.zeros(n)
    if infeasible:
        bad = draw(hnp.arrays(np.bool_, (n,)))
        if distinct_cv:
            values = np.arange(1, n + 1, dtype=float)[draw(st.permutations(range(n)))]
        else:
            values = draw(hnp.arrays(np.int64, (n,), elements=st.integers(1, 3))).astype(float)
        cv = np.where(bad, values * 0.25, 0.0)
    return F, cv


# ----------------------------------------------------------------------------- dominance
def test_total_violation_sums_positive_parts_like_pymoo():
    rng = np.random.default_rng(0)
    G = rng.normal(size=(20, 24))
    G[:5] = -np.abs(G[:5])
    pop = Population.new("G", G)
    expected = pop.get("CV")[:, 0]
    with jax.enable_x64(True):
        got = np.asarray(pareto.total_violation(G))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert (got[:5] == 0).all()


@given(populations(distinct_cv=True))
def test_constrained_dominance_equals_pymoo_dominator_for_distinct_violations(pop):
    F, cv = pop
    with jax.enable_x64(True):
        D = np.asarray(dominance(F, cv))
    np.testing.assert_array_equal(D, pymoo_dominance(F, cv))


@given(populations(infeasible=True))
def test_constrained_dominance_follows_documented_rule_with_equal_violations(pop):
    F, cv = pop
    with jax.enable_x64(True):
        D = np.asarray(dominance(F, cv))
    np.testing.assert_array_equal(D, documented_dominance(F, cv))
    assert not D.diagonal().any()


def test_equal_violation_is_where_we_differ_from_pymoo():
    F = np.array([[0.0, 0.0], [1.0, 1.0]])
    cv = np.array([2.0, 2.0])
    assert Dominator.get_relation(F[0], F[1], cv[0], cv[1]) == 1  # pymoo: Pareto on F
    with jax.enable_x64(True):
        assert not np.asarray(dominance(F, cv)).any()  # ours: same front
        assert np.asarray(rank_general(F, cv)).tolist() == [0, 0]
        assert np.asarray(rank_2d(F, cv)).tolist() == [0, 0]


# ----------------------------------------------------------------------------- ranks
@given(populations(infeasible=False))
def test_ranks_of_feasible_sets_equal_pymoo_nondominated_sorting(pop):
    F, cv = pop
    expected = pymoo_ranks(F)
    with jax.enable_x64(True):
        np.testing.assert_array_equal(np.asarray(rank_general(F, cv)), expected)
        if F.shape[1] == 2:
            np.testing.assert_array_equal(np.asarray(rank_2d(F, cv)), expected)


@given(populations(m=2, integer=True, infeasible=False))
def test_rank_2d_equals_pymoo_on_integer_sets_with_duplicates(pop):
    F, cv = pop
    half = len(F) // 2
    F[len(F) - half :] = F[:half]  # exact duplicates for sure
    with jax.enable_x64(True):
        got = np.asarray(rank_2d(F, cv))
    np.testing.assert_array_equal(got, pymoo_ranks(F))


@given(populations(distinct_cv=True))
def test_constrained_ranks_equal_peel_of_pymoo_dominator(pop):
    F, cv = pop
    expected = peel(pymoo_dominance(F, cv))
    with jax.enable_x64(True):
        np.testing.assert_array_equal(np.asarray(rank_general(F, cv)), expected)
        if F.shape[1] == 2:
            np.testing.assert_array_equal(np.asarray(rank_2d(F, cv)), expected)


@given(populations(m=2))
def test_rank_2d_equals_general_rank_with_ties_duplicates_and_equal_violations(pop):
    F, cv = pop
    expected = peel(documented_dominance(F, cv))
    with jax.enable_x64(True):
        general = np.asarray(rank_general(F, cv))
        fast = np.asarray(rank_2d(F, cv))
    np.testing.assert_array_equal(general, expected)
    np.testing.assert_array_equal(fast, general)
    assert general.dtype == np.int32 and fast.dtype == np.int32


@given(populations(m=2), st.sampled_from((1, 5, 16)))
def test_rank_stop_after_keeps_the_fronts_it_needs(pop, stop_after):
    """Peeling stops at the first front that brings the ranked count to ``stop_after``;
    ranks up to that front are the full peel's, the rest share the next index."""
    F, cv = pop
    expected = peel(documented_dominance(F, cv))
    with jax.enable_x64(True):
        got = np.asarray(jax.jit(pareto.nondominated_rank, static_argnums=2)(F, cv, stop_after))
    counts = np.cumsum(np.bincount(expected))
    last = int(np.searchsorted(counts, min(stop_after, len(F))))  # front reaching the count
    keep = expected <= last
    np.testing.assert_array_equal(got[keep], expected[keep])
    assert np.all(got[~keep] == last + 1)


def test_infeasible_members_follow_last_feasible_front_by_violation():
    F = np.array([[0.0, 3.0], [1.0, 1.0], [2.0, 2.0], [-5.0, -5.0], [-5.0, -5.0], [9.0, 9.0]])
    cv = np.array([0.0, 0.0, 0.0, 0.5, 0.2, 0.2])
    expected = [0, 0, 1, 3, 2, 2]
    with jax.enable_x64(True):
        assert np.asarray(rank_general(F, cv)).tolist() == expected
        assert np.asarray(rank_2d(F, cv)).tolist() == expected
    allbad = np.array([0.3, 0.1, 0.3, 0.2, 0.1, 0.4])
    with jax.enable_x64(True):
        assert np.asarray(rank_2d(F, allbad)).tolist() == [2, 0, 2, 1, 0, 3]


def test_rank_2d_rejects_other_objective_counts():
    with pytest.raises(ValueError):
        pareto.nondominated_rank_2d(np.zeros((4, 3)), np.zeros(4))


# ----------------------------------------------------------------------------- crowding
def test_crowding_distance_hand_example():
    # one front of four points, one of three, one singleton, one pair
    F = np.array(
        [[0, 4], [1, 2], [3, 1], [4, 0], [1, 5], [3, 3], [5, 1], [9, 9], [6, 7], [7, 6]], float
    )
    rank = np.array([0, 0, 0, 0, 1, 1, 1, 2, 3, 3])
    with jax.enable_x64(True):
        cd = np.asarray(crowding(F, rank))
    inf = np.inf
    expected = [inf, 3 / 4 + 3 / 4, 3 / 4 + 2 / 4, inf, inf, 4 / 4 + 4 / 4, inf, inf, inf, inf]
    np.testing.assert_allclose(cd, expected, rtol=0, atol=1e-15)


def test_crowding_skips_objective_with_zero_range_in_front():
    # second objective is constant in the front: it adds nothing, not even +inf at the ends
    F = np.array([[0.0, 1.0], [1.0, 1.0], [3.0, 1.0], [4.0, 1.0]])
    rank = np.zeros(4, np.int32)
    with jax.enable_x64(True):
        cd = np.asarray(crowding(F, rank))
    np.testing.assert_allclose(cd, [np.inf, 3 / 4, 3 / 4, np.inf])
    same = np.ones((5, 2))
    with jax.enable_x64(True):
        np.testing.assert_array_equal(np.asarray(crowding(same, np.zeros(5, np.int32))), 0.0)


def _check_crowding_against_pymoo(F: np.ndarray) -> None:
    cd_pymoo = get_crowding_function("cd")
    m = F.shape[1]
    cv = np.zeros(len(F))
    with jax.enable_x64(True):
        rank = np.asarray(rank_general(F, cv))
        cd = np.asarray(crowding(F, rank))
    assert cd.dtype == np.float64
    for k in range(rank.max() + 1):
        front = np.flatnonzero(rank == k)
        # pymoo divides the sum over objectives by m; we follow Deb 2002 (no division)
        expected = cd_pymoo.do(F[front]) * m
        np.testing.assert_array_equal(np.isinf(cd[front]), np.isinf(expected))
        finite = np.isfinite(expected)
        np.testing.assert_allclose(cd[front][finite], expected[finite], rtol=0, atol=1e-12)


@pytest.mark.parametrize("m", [2, 3])
@pytest.mark.parametrize("seed", range(4))
def test_crowding_distance_equals_pymoo_per_front_without_duplicates(m, seed):
    rng = np.random.default_rng(seed)
    F = rng.random((32, m))
    F[:, 0] = F[:, 0] * 10 + 5  # objectives on different scales
    assert len(np.unique(F, axis=0)) == len(F)
    _check_crowding_against_pymoo(F)


@given(populations(integer=True, infeasible=False))
def test_crowding_with_duplicates_orders_ties_by_index_like_pymoo_cd(pop):
    # documented rule: duplicates are kept and ordered by index; pymoo 0.6.2's "cd" agrees
    F, _ = pop
    _check_crowding_against_pymoo(F)


# ----------------------------------------------------------------------------- survival
def pymoo_survivors(F: np.ndarray, cv: np.ndarray, n_survive: int, seed: int) -> np.ndarray:
    G = cv[:, None]  # one constraint whose positive part is the violation
    problem = Problem(n_var=1, n_obj=F.shape[1], n_ieq_constr=1)
    pop = Population.new("F", F, "G", G)
    idx = RankAndCrowding().do(
        problem, pop, n_survive=n_survive, random_state=np.random.default_rng(seed),
        return_indices=True,
    )
    return np.asarray(idx)


@pytest.mark.parametrize("m", [2, 3])
@pytest.mark.parametrize("case", ["feasible", "infeasible", "integer"])
@pytest.mark.parametrize("seed", range(3))
def test_survivors_equal_pymoo_rank_and_crowding_up_to_exact_ties(m, case, seed):
    rng = np.random.default_rng(100 + seed)
    n = 32
    if case == "integer":
        F = rng.integers(0, 5, (n, m)).astype(float)  # many crowding ties
    else:
        F = rng.random((n, m))
    cv = np.zeros(n)
    if case == "infeasible":
        bad = rng.random(n) < 0.4
        cv[bad] = rng.permutation(n)[: bad.sum()] + 1.0  # distinct violations
    with jax.enable_x64(True):
        rank = rank_general(F, cv)
        rank, cd = np.asarray(rank), np.asarray(crowding(F, rank))
    for n_survive in (7, 20):
        with jax.enable_x64(True):
            ours = np.asarray(survive(F, cv, n_survive))
        theirs = pymoo_survivors(F, cv, n_survive, seed)
        assert ours.dtype == np.int32 and len(np.unique(ours)) == n_survive
        assert len(theirs) == n_survive
        diff = np.setxor1d(ours, theirs)
        if diff.size:
            assert len(set(rank[diff].tolist())) == 1, (rank[diff], cd[diff])
            assert len(set(cd[diff].tolist())) == 1, (rank[diff], cd[diff])


def test_survive_orders_by_rank_then_larger_crowding_then_index():
    rng = np.random.default_rng(7)
    F = rng.integers(0, 4, (32, 2)).astype(float)
    cv = np.where(rng.random(32) < 0.3, rng.integers(1, 3, 32), 0).astype(float)
    with jax.enable_x64(True):
        order = np.asarray(survive(F, cv, 32))
        rank = rank_general(F, cv)
        rank, cd = np.asarray(rank), np.asarray(crowding(F, rank))
    assert sorted(order.tolist()) == list(range(32))
    keys = [(rank[i], -cd[i], i) for i in order]
    assert keys == sorted(keys)
    # infeasible members come after every feasible one, in order of violation
    feasible = cv[order] == 0
    assert not (feasible[1:] & ~feasible[:-1]).any()
    assert (np.diff(cv[order][~feasible]) >= 0).all()


# ----------------------------------------------------------------------------- jit, vmap, dtypes
def test_vmap_over_populations_equals_python_loop():
    # two objectives, so that survive's vmap goes through nondominated_rank_2d as well
    m = 2
    rng = np.random.default_rng(3)
    B, n = 3, 32
    F = rng.integers(0, 4, (B, n, m)).astype(float)
    cv = np.where(rng.random((B, n)) < 0.3, rng.integers(1, 3, (B, n)), 0).astype(float)
    with jax.enable_x64(True):  # shapes shared with the tests above: fewer compilations
        ranks = jax.jit(jax.vmap(pareto.nondominated_rank))(F, cv)
        ranks2 = jax.jit(jax.vmap(pareto.nondominated_rank_2d))(F, cv)
        cds = jax.jit(jax.vmap(pareto.crowding_distance))(F, ranks)
        kept = jax.jit(jax.vmap(functools.partial(pareto.survive, n_survive=20)))(F, cv)
        loop = [
            (rank_general(F[b], cv[b]), crowding(F[b], ranks[b]), survive(F[b], cv[b], 20))
            for b in range(B)
        ]
    assert kept.shape == (B, 20)
    np.testing.assert_array_equal(ranks2, ranks)
    for b, (rank, cd, kept_b) in enumerate(loop):
        np.testing.assert_array_equal(ranks[b], rank)
        np.testing.assert_array_equal(cds[b], cd)
        np.testing.assert_array_equal(kept[b], kept_b)


def test_float32_outside_x64_context():
    rng = np.random.default_rng(5)
    F = jnp.asarray(rng.random((32, 2)), jnp.float32)
    G = jnp.asarray(rng.normal(size=(32, 3)) - 1.0, jnp.float32)
    cv = total_violation(G)
    rank, cd = rank_and_crowding(F, cv)
    assert cv.dtype == jnp.float32 and cd.dtype == jnp.float32 and rank.dtype == jnp.int32
    F64 = np.asarray(F, np.float64)
    cv64 = np.asarray(cv, np.float64)
    np.testing.assert_array_equal(rank, peel(pymoo_dominance(F64, cv64)))
    np.testing.assert_array_equal(rank_general(F, cv), rank)
    expected = np.zeros(32)
    for k in range(int(rank.max()) + 1):
        front = np.flatnonzero(np.asarray(rank) == k)
        expected[front] = get_crowding_function("cd").do(F64[front]) * 2
    np.testing.assert_allclose(np.asarray(cd), expected, rtol=1e-5)
    assert survive(F, cv, 10).dtype == jnp.int32


# ----------------------------------------------------------------------------- packed lexsort
# Values with ties and every special float: lax.sort treats -0.0 as +0.0 and puts NaNs last.
SPECIAL = (-np.inf, -2.5, -1.0, -0.0, 0.0, 1e-300, 1.0, 2.5, np.inf, np.nan)


@st.composite
def key_sets(draw):
    """1–3 sort keys of one length (bool, int32, float32 or float64), many ties."""
    n = draw(st.sampled_from((1, 7, 300)))
    keys = []
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(("bool", "int32", "float32", "float64")))
        if kind == "bool":
            keys.append(draw(hnp.arrays(np.bool_, n)))
        elif kind == "int32":
            keys.append(draw(hnp.arrays(np.int32, n, elements=st.integers(-3, 3))))
        else:
            pool = np.asarray(SPECIAL, kind)
            keys.append(pool[draw(hnp.arrays(np.int64, n, elements=st.integers(0, len(pool) - 1)))])
    return keys


lexsort_jit = jax.jit(lambda keys: pareto.lexsort(keys, packed=True))  # at every size
reference_lexsort = jax.jit(lambda keys: jnp.lexsort(keys))


@given(key_sets())
def test_packed_lexsort_equals_jax_lexsort(keys):
    """``pareto.lexsort`` packs every key's ordinal and the index into one int64 and sorts
    that: it must give JAX's ``lexsort`` permutation exactly (ties by index), -0.0, NaN and
    infinities included. Without NaN and -0.0, NumPy's lexsort agrees too."""
    with jax.enable_x64(True):
        ours = np.asarray(lexsort_jit(keys))
        theirs = np.asarray(reference_lexsort(keys))
        batched = np.asarray(lexsort_jit([np.stack([k, k[::-1]]) for k in keys]))
        theirs_reversed = np.asarray(reference_lexsort([k[::-1] for k in keys]))
    assert ours.dtype == np.int32
    np.testing.assert_array_equal(ours, theirs)
    np.testing.assert_array_equal(batched[0], theirs)
    np.testing.assert_array_equal(batched[1], theirs_reversed)
    plain = [np.where(k == 0, 0, k) if k.dtype.kind == "f" else k for k in keys]
    if not any(np.isnan(k).any() for k in plain if k.dtype.kind == "f"):
        np.testing.assert_array_equal(ours, np.lexsort(plain, axis=-1))


def test_packed_lexsort_falls_back_to_jax_lexsort():
    """Without 64-bit integers (JAX's default), or when the packed key would need more than
    63 bits (4 fields of 16 bits for 65,536 members), the permutation is JAX's own."""
    rng = np.random.default_rng(5)
    small = [rng.integers(0, 3, 50).astype(np.float32), rng.integers(0, 3, 50).astype(np.int32)]
    np.testing.assert_array_equal(pareto.lexsort(small, packed=True), jnp.lexsort(small))
    big = [rng.integers(0, 9, 2**16).astype(np.float64) for _ in range(3)]
    with jax.enable_x64(True):
        np.testing.assert_array_equal(pareto.lexsort(big), jnp.lexsort(big))
        assert np.asarray(pareto.lexsort(big)).dtype == np.int32
        # below PACKED_MIN members JAX's own sort is used unless packing is asked for
        few = [rng.integers(0, 3, pareto.PACKED_MIN - 1).astype(np.float64) for _ in range(2)]
        np.testing.assert_array_equal(pareto.lexsort(few), jnp.lexsort(few))


def test_packed_lexsort_rejects_bad_keys():
    with pytest.raises(ValueError, match="at least one key"):
        pareto.lexsort([])
    with pytest.raises(ValueError, match="share one shape"):
        pareto.lexsort([np.zeros(3), np.zeros(4)])
