"""NSGA-II, MOPSO and their operators (dockjax.algorithms.{variation, nsga2, mopso}).

References: pymoo 0.6.2's NSGA-II on its own ZDT1 for NSGA-II; for MOPSO (absent from
pymoo) a sequential NumPy implementation of Coello et al. 2004 written below from
conventions §10 and the paper's reference code (particles enter the repository one at a time,
the grid is recomputed only when needed, the crowded-cube member is replaced at random).
IGD is plain NumPy against 1000 points of ZDT1's analytic front. Runs are float64 and each
algorithm compiles once for its five seeds (vmapped).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dockjax import pareto
from dockjax.algorithms import ALGORITHMS, base, mopso, nsga2, variation
from dockjax.algorithms.variation import binary_tournament
from dockjax.algorithms.zdt import ZDT1

# Jitted once per shape: one compiled program each instead of many eager primitives.
sbx = jax.jit(variation.sbx)
polynomial_mutation = jax.jit(variation.polynomial_mutation)

SEEDS = tuple(range(5))
POP, ITERS = 100, 100
FRONT = ZDT1.pareto_front(1000)


def igd(F: np.ndarray) -> float:
    """Mean distance from each reference-front point to the nearest point of F."""
    d = np.sqrt(((FRONT[:, None, :] - np.asarray(F)[None, :, :]) ** 2).sum(-1))
    return float(d.min(axis=1).mean())


def first_front(F: np.ndarray) -> np.ndarray:
    """Pareto non-dominated rows of F (plain NumPy)."""
    dom = np.all(F[:, None] <= F[None], -1) & np.any(F[:, None] < F[None], -1)
    return F[~dom.any(axis=0)]


# ----------------------------------------------------------------------------- operators


def test_sbx_children_stay_in_unit_box_including_parents_on_the_bounds():
    key = jax.random.key(0)
    A = jax.random.uniform(jax.random.key(1), (500, 8))
    B = jax.random.uniform(jax.random.key(2), (500, 8))
    A = A.at[:, 0].set(0.0).at[:, 1].set(1.0)  # parents on the bounds
    ca, cb = sbx(key, A, B, prob=1.0)
    for c in (ca, cb):
        assert np.all(np.isfinite(c)) and np.all((c >= 0) & (c <= 1))
    # Some variables actually changed (about prob_var of them).
    changed = np.mean(np.asarray(ca) != np.asarray(A))
    assert 0.3 < changed < 0.7


def test_sbx_with_identical_parents_returns_the_parents():
    P = jax.random.uniform(jax.random.key(3), (64, 10))
    ca, cb = sbx(jax.random.key(4), P, P, prob=1.0, prob_var=1.0)
    np.testing.assert_array_equal(np.asarray(ca), np.asarray(P))
    np.testing.assert_array_equal(np.asarray(cb), np.asarray(P))


def test_sbx_with_zero_pair_probability_returns_the_parents():
    A = jax.random.uniform(jax.random.key(5), (32, 6))
    B = jax.random.uniform(jax.random.key(6), (32, 6))
    ca, cb = sbx(jax.random.key(7), A, B, prob=0.0)
    np.testing.assert_array_equal(np.asarray(ca), np.asarray(A))
    np.testing.assert_array_equal(np.asarray(cb), np.asarray(B))


def test_sbx_preserves_each_pairs_mean_away_from_the_bounds():
    # Far from the bounds β → ∞, α = 2 to rounding, both β_q coincide: c1 + c2 = y1 + y2.
    with jax.enable_x64(True):
        A = jax.random.uniform(jax.random.key(8), (2000, 5), jnp.float64, 0.45, 0.55)
        B = jax.random.uniform(jax.random.key(9), (2000, 5), jnp.float64, 0.45, 0.55)
        ca, cb = sbx(jax.random.key(10), A, B, prob=1.0, prob_var=1.0)
        np.testing.assert_allclose(np.asarray(ca + cb), np.asarray(A + B), rtol=0, atol=1e-9)
        assert np.mean(np.asarray(ca) != np.asarray(A)) > 0.99  # they were crossed


def test_sbx_spread_matches_its_distribution_index():
    # Unbounded SBX: β = |c2 − c1| / |y2 − y1| has P(β ≤ 1) = 1/2 for every η.
    with jax.enable_x64(True):
        A = jnp.full((20000, 1), 0.49, jnp.float64)
        B = jnp.full((20000, 1), 0.51, jnp.float64)
        ca, cb = sbx(jax.random.key(11), A, B, eta=15.0, prob=1.0, prob_var=1.0)
        beta = np.abs(np.asarray(cb - ca)) / 0.02
        assert abs(np.mean(beta <= 1.0) - 0.5) < 0.02


def test_polynomial_mutation_stays_in_box_and_changes_one_variable_on_average():
    n, d = 10000, 30
    X = jax.random.uniform(jax.random.key(12), (n, d))
    Y = np.asarray(polynomial_mutation(jax.random.key(13), X, eta=20.0))
    assert np.all(np.isfinite(Y)) and np.all((Y >= 0) & (Y <= 1))
    changed = (Y != np.asarray(X)).sum(axis=1)
    # Binomial(30, 1/30) per individual: mean 1, standard error of the mean ~0.01.
    assert abs(changed.mean() - 1.0) < 0.05
    # On the bounds: a value at 0 (1) can only move up (down), and stays in the box.
    Xb = X.at[:, 0].set(0.0).at[:, 1].set(1.0)
    Yb = np.asarray(polynomial_mutation(jax.random.key(14), Xb, prob_var=1.0))
    assert np.all((Yb >= 0) & (Yb <= 1))
    assert np.mean(Yb[:, 0] > 0) > 0.4 and np.mean(Yb[:, 1] < 1) > 0.4
    # Small steps on average (η = 20): E|δ_q| is a few hundredths.
    step = np.abs(Y - np.asarray(X))[Y != np.asarray(X)]
    assert 0.0 < np.median(step) < 0.1


def test_polynomial_mutation_probability_is_respected():
    X = jax.random.uniform(jax.random.key(14), (2000, 10))
    Y = polynomial_mutation(jax.random.key(15), X, prob_var=0.0)
    np.testing.assert_array_equal(np.asarray(Y), np.asarray(X))
    Y = np.asarray(polynomial_mutation(jax.random.key(16), X, prob_var=0.5))
    assert abs(np.mean(Y != np.asarray(X)) - 0.5) < 0.02


_tournament = jax.jit(binary_tournament, static_argnames="n")
_update_repository = jax.jit(mopso.update_repository, static_argnames="n_div")


def _tournament_winners(rank, crowding, cv, n=400, seed=0):
    return np.asarray(
        _tournament(
            jax.random.key(seed), jnp.asarray(rank), jnp.asarray(crowding, jnp.float32),
            jnp.asarray(cv, jnp.float32), n=n,
        )
    )


def test_tournament_feasible_beats_infeasible_even_with_worse_rank():
    # Member 0 is infeasible with the best rank and crowding; member 1 is feasible.
    w = _tournament_winners([0, 5], [np.inf, 0.0], [0.3, 0.0])
    assert set(w) == {1}


def test_tournament_smaller_violation_wins_among_infeasible():
    w = _tournament_winners([0, 1], [np.inf, np.inf], [2.0, 0.5])
    assert set(w) == {1}


def test_tournament_lower_rank_wins_among_feasible_then_larger_crowding():
    w = _tournament_winners([1, 0], [np.inf, 0.1], [0.0, 0.0])
    assert set(w) == {1}
    w = _tournament_winners([0, 0], [0.2, 0.7], [0.0, 0.0])
    assert set(w) == {1}


def test_tournament_full_ties_go_either_way_and_draw_from_permutations():
    w = _tournament_winners([0, 0, 0, 0], [1.0] * 4, [0.0] * 4, n=4000)
    counts = np.bincount(w, minlength=4)
    assert np.all(np.abs(counts / 4000 - 0.25) < 0.03)
    # Each member takes part in exactly 2n/N tournaments: with N = n every member enters
    # two, so the best member (unique rank 0) wins exactly twice.
    w = _tournament_winners(np.arange(10), np.ones(10), np.zeros(10), n=10)
    assert np.sum(w == 0) == 2


# ----------------------------------------------------------------------------- contracts


class CountingZDT1(ZDT1):
    """ZDT1 recording how many candidates each traced evaluation scores."""

    calls: list[int] = []

    def evaluate_jax(self, X):
        CountingZDT1.calls.append(X.shape[0])
        return super().evaluate_jax(X)


jax.tree_util.register_pytree_node(
    CountingZDT1, lambda p: ((), p.n_var), lambda n, _: CountingZDT1(n)
)


@pytest.mark.parametrize("algo,params", [
    (nsga2.ALGORITHM, nsga2.Params(pop_size=7)),  # odd population: ceil(7/2) pairs, one child dropped
    (mopso.ALGORITHM, mopso.Params(pop_size=6, max_iter=3)),
])
def test_init_and_step_evaluate_exactly_pop_size_candidates(algo, params):
    # Traced only (eval_shape): the evaluation count is a property of the program.
    problem = CountingZDT1(n_var=4)
    algo.validate(params)
    CountingZDT1.calls.clear()
    state = jax.eval_shape(lambda k: algo.init(k, problem, params), jax.random.key(0))
    assert CountingZDT1.calls == [params.pop_size]
    CountingZDT1.calls.clear()
    after = jax.eval_shape(lambda s: algo.step(s, problem, params), state)
    assert CountingZDT1.calls == [params.pop_size]
    assert jax.tree_util.tree_map(lambda a: (a.shape, a.dtype), after) == jax.tree_util.tree_map(
        lambda a: (a.shape, a.dtype), state
    )
    pop = algo.final_population(after)
    assert pop.U.shape == (params.pop_size, 4) and pop.F.shape == (params.pop_size, 2)


@pytest.mark.parametrize("bad", [
    dict(eta_c=0.0), dict(eta_c=-1.0), dict(p_crossover=1.5), dict(p_crossover=-0.1), dict(eta_m=0.0),
    dict(p_mutation=2.0), dict(p_mutation=-0.5), dict(pop_size=3), dict(eta_c=float("nan")),
])
def test_nsga2_validate_rejects_bad_hyper_parameters(bad):
    with pytest.raises(ValueError):
        base.validate_params(nsga2.Params(**bad))


@pytest.mark.parametrize("bad", [
    dict(w=-0.1), dict(w=1.5), dict(mutation_rate=1.5), dict(n_div=0), dict(max_iter=0),
    dict(pop_size=2),
])
def test_mopso_validate_rejects_bad_hyper_parameters(bad):
    with pytest.raises(ValueError):
        base.validate_params(mopso.Params(**bad))


def test_validate_accepts_defaults_and_the_one_over_n_sentinel():
    base.validate_params(nsga2.Params())
    base.validate_params(nsga2.Params(pop_size=5, p_mutation=0.1))
    base.validate_params(nsga2.Params(p_mutation=np.array([-1.0, 0.2])))  # a batch of values
    base.validate_params(mopso.Params())


def test_repository_truncation_empties_the_most_crowded_cube_first():
    # Nine mutually non-dominated points for a capacity of 6: five crowd the cube at the
    # top-left corner (one of them already in the repository), four lie apart. Three must
    # go, all from the crowd: the incumbent stays, then the earliest newcomer.
    crowd = np.array([[0.0, 1.0], [0.001, 0.999], [0.002, 0.998], [0.003, 0.997], [0.004, 0.996]])
    apart = np.array([[0.3, 0.7], [0.5, 0.5], [0.7, 0.3], [1.0, 0.0]])

    def population(F):
        F = jnp.asarray(F)
        n = F.shape[0]
        return base.Population(U=jnp.zeros((n, 2)), F=F, G=jnp.zeros((n, 0)), cv=jnp.zeros(n))

    k = 6
    repo = population(np.vstack([crowd[4:], np.zeros((k - 1, 2))]))
    valid = jnp.arange(k) == 0
    new = population(np.vstack([crowd[:4], apart]))
    repo, valid = _update_repository(repo, valid, new, n_div=30)
    assert int(valid.sum()) == k
    kept = np.asarray(repo.F)[np.asarray(valid)]
    np.testing.assert_allclose(kept, np.vstack([crowd[4], crowd[0], apart]), atol=1e-6)
    assert np.all(np.isinf(np.asarray(repo.F)[~np.asarray(valid)]))


def test_repository_rejects_dominated_and_duplicate_members():
    F = jnp.asarray([[0.0, 1.0], [0.5, 0.5], [0.6, 0.6], [0.5, 0.5], [1.0, 0.0], [0.2, 0.9]])
    cand = base.Population(U=jnp.zeros((6, 1)), F=F, G=jnp.zeros((6, 0)), cv=jnp.zeros(6))
    empty = jax.tree_util.tree_map(lambda a: a[:4], cand)
    repo, valid = _update_repository(empty, jnp.zeros(4, bool), cand, n_div=30)
    got = np.asarray(repo.F)[np.asarray(valid)]
    np.testing.assert_allclose(got, [[0.0, 1.0], [0.5, 0.5], [1.0, 0.0], [0.2, 0.9]], atol=1e-6)
    # Constrained: a feasible member evicts every infeasible one.
    cv = jnp.asarray([0.0, 0.3, 0.0, 0.1, 0.2, 0.0])
    cand = dataclasses.replace(cand, cv=cv)
    repo, valid = _update_repository(empty, jnp.zeros(4, bool), cand, n_div=30)
    assert np.all(np.asarray(repo.cv)[np.asarray(valid)] == 0)
    assert np.all(np.isinf(np.asarray(repo.cv)[~np.asarray(valid)]))



@pytest.mark.parametrize("name", list(ALGORITHMS))
def test_the_scan_driver_the_host_driver_and_init_then_steps_agree(name):
    """``optimize``'s two drivers — ``"scan"`` (``base.run_batch``: one scan that scores at
    one site, ``init_ask``/``ask``, evaluate, ``init_tell``/``tell``) and ``"host"`` (a
    Python loop of vmapped ask, one kernel call for every run, vmapped tell) — must give the
    same final populations and histories up to rounding (the programs fuse differently),
    per-run hyper-parameters included; and run 0 must be what ``Algorithm.init`` followed by
    ``Algorithm.step`` n times gives, its history included."""
    from dockjax import prng
    from dockjax.algorithms import get, make_params
    from dockjax.metrics import hypervolume_2d
    from dockjax.optimize import optimize

    algo, problem, n_iter, hv_ref = get(name), ZDT1(n_var=5), 4, np.array([1.2, 6.0])
    per_run = {"rho": [0.3, 0.4, 0.6]} if name == "imocs" else {}
    kw = dict(seeds=[3, 4, 5], pop_size=10, n_iter=n_iter, hv_ref=hv_ref, **per_run)
    scan = optimize(name, problem, driver="scan", **kw)
    host = optimize(name, problem, driver="host", **kw)
    np.testing.assert_allclose(host.U, scan.U, rtol=0, atol=1e-12)
    finite = np.isfinite(scan.F)
    assert np.array_equal(finite, np.isfinite(host.F))
    np.testing.assert_allclose(host.F[finite], scan.F[finite], rtol=1e-12)
    np.testing.assert_array_equal(host.front, scan.front)
    assert host.history.shape == scan.history.shape == (3, n_iter)
    np.testing.assert_allclose(host.history, scan.history, rtol=1e-12)
    # the batch really differs run by run (seeds and, for IMOCS, rho)
    assert not np.allclose(scan.U[0], scan.U[1])
    # run 0 by hand: init, then n steps
    params = make_params(algo, 10, n_iter, **{k: v[0] for k, v in per_run.items()})
    with jax.enable_x64(True):
        s = jax.jit(lambda k: algo.init(k, problem, params))(prng.key(3))
        one_step = jax.jit(lambda s: algo.step(s, problem, params))
        history = []
        for _ in range(n_iter):
            s = one_step(s)
            pop = algo.final_population(s)
            history.append(float(hypervolume_2d(pop.F, pop.cv <= 0, jnp.asarray(hv_ref))))
        pop = _to_numpy(algo.final_population(s))
    np.testing.assert_allclose(pop.U, scan.U[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(pop.F[np.isfinite(pop.F)], scan.F[0][finite[0]], rtol=1e-12)
    np.testing.assert_allclose(history, scan.history[0], rtol=1e-12)


@pytest.mark.parametrize("bad, match", [
    (dict(devices=0), "devices must be an integer from 1 to 1"),
    (dict(devices=2), "devices must be an integer from 1 to 1"),
    (dict(devices=True), "devices must be an integer"),
    (dict(devices=1.0), "devices must be an integer"),
])
def test_bad_device_counts_are_rejected(bad, match):
    """The test processes have one CPU device (the two-device path is checked in a
    subprocess, tests/test_xla_settings.py)."""
    from dockjax.optimize import optimize

    assert len(jax.local_devices()) == 1
    with pytest.raises(ValueError, match=match):
        optimize("nsga2", ZDT1(n_var=5), seeds=[0, 1], pop_size=10, n_iter=2, **bad)


# ----------------------------------------------------------------------------- ZDT1 runs


def _to_numpy(tree):
    return jax.tree_util.tree_map(
        lambda a: np.asarray(jax.random.key_data(a))
        if jnp.issubdtype(a.dtype, jax.dtypes.prng_key) else np.asarray(a),
        tree,
    )


def _batched(algo, params):
    run_fn = jax.jit(jax.vmap(lambda k: base.run(algo, k, ZDT1(), params, ITERS)[0]))
    keys = jax.vmap(jax.random.key)(jnp.asarray(SEEDS))
    return run_fn, keys


@functools.lru_cache(maxsize=None)
def nsga2_runs():
    with jax.enable_x64(True):
        run_fn, keys = _batched(nsga2.ALGORITHM, nsga2.Params(pop_size=POP))
        first = _to_numpy(run_fn(keys))
        again = _to_numpy(run_fn(keys))
    return first, again


@functools.lru_cache(maxsize=None)
def mopso_runs():
    with jax.enable_x64(True):
        run_fn, keys = _batched(mopso.ALGORITHM, mopso.Params(pop_size=POP, max_iter=ITERS))
        first = _to_numpy(run_fn(keys))
        again = _to_numpy(run_fn(keys))
    return first, again




def nsga2_igd() -> float:
    state, _ = nsga2_runs()
    return float(np.median([igd(first_front(state.pop.F[i])) for i in range(len(SEEDS))]))


def mopso_igd() -> float:
    state, _ = mopso_runs()
    return float(np.median([
        igd(state.repository.F[i][state.archive_valid[i]]) for i in range(len(SEEDS))
    ]))


def test_nsga2_zdt1_median_igd_within_25_percent_of_pymoo(pymoo_zdt1_igd):
    ours, theirs = nsga2_igd(), pymoo_zdt1_igd
    print(f"NSGA-II ZDT1 median IGD: dockjax {ours:.5f}, pymoo {theirs:.5f}")
    assert ours <= 1.25 * theirs
    assert ours >= 0.5 * theirs  # not implausibly better either


def test_nsga2_same_key_gives_bit_identical_runs():
    first, again = nsga2_runs()
    for a, b in zip(jax.tree_util.tree_leaves(first), jax.tree_util.tree_leaves(again)):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(first.pop.F[0], first.pop.F[1])  # seeds differ


def test_nsga2_state_ranks_and_crowding_describe_the_population():
    state, _ = nsga2_runs()
    with jax.enable_x64(True):
        for i in range(len(SEEDS)):
            rank, cd = pareto.rank_and_crowding(
                jnp.asarray(state.pop.F[i]), jnp.asarray(state.pop.cv[i])
            )
            np.testing.assert_array_equal(state.rank[i], np.asarray(rank))
            np.testing.assert_array_equal(state.crowding[i], np.asarray(cd))
            assert np.all((state.pop.U[i] >= 0) & (state.pop.U[i] <= 1))
    assert np.all(state.iteration == ITERS)


def _zdt1(X):
    f1 = X[:, 0]
    g = 1.0 + 9.0 * X[:, 1:].mean(axis=1)
    return np.stack([f1, g * (1.0 - np.sqrt(f1 / g))], axis=1)


def reference_mopso(seed, n=POP, T=ITERS, d=30, w=0.4, ndiv=30, p_m=0.5):
    """Sequential MOPSO (Coello et al. 2004) on ZDT1 in NumPy; returns the repository's F.

    Each particle enters the repository on its own: rejected if a member dominates or
    equals it, else it removes the members it dominates; when the repository is full it
    replaces a random member of the most crowded cube if it falls outside the grid or in a
    less crowded cube, else it is discarded. Leaders by roulette on 10/count over cubes,
    then uniformly in the cube.
    """
    rng = np.random.default_rng(seed)
    X = rng.random((n, d))
    V = np.zeros((n, d))
    F = _zdt1(X)
    PB, PF = X.copy(), F.copy()

    def dominates(a, b):
        return np.all(a <= b, -1) & np.any(a < b, -1)

    def grid(fs):
        lo, hi = fs.min(0), fs.max(0)
        return lo, np.where(hi > lo, hi - lo, 1.0)

    def cube_ids(fs, lo, width):
        c = np.floor((fs - lo) / width * ndiv)
        inside = np.all((c >= 0) & (c <= ndiv), -1)
        c = np.clip(c, 0, ndiv - 1).astype(np.int64)
        return c @ (ndiv ** np.arange(fs.shape[-1])), inside

    def insert(x, f, RX, RF):
        if len(RF) and (np.any(dominates(RF, f)) or np.any(np.all(RF == f, 1))):
            return RX, RF
        keep = ~dominates(f, RF)
        RX, RF = RX[keep], RF[keep]
        if len(RF) < n:
            return np.vstack([RX, x[None]]), np.vstack([RF, f[None]])
        lo, width = grid(RF)
        ids, _ = cube_ids(RF, lo, width)
        uniq, inv, counts = np.unique(ids, return_inverse=True, return_counts=True)
        most = np.argmax(counts)
        mine, inside = cube_ids(f[None], lo, width)
        if not inside[0] or counts[uniq == mine[0]].sum() < counts[most]:
            members = np.flatnonzero(inv == most)
            i = members[rng.integers(len(members))]
            RX, RF = RX.copy(), RF.copy()
            RX[i], RF[i] = x, f
        return RX, RF

    RX, RF = np.empty((0, d)), np.empty((0, 2))
    for i in range(n):
        RX, RF = insert(X[i], F[i], RX, RF)
    for t in range(T):
        lo, width = grid(RF)
        ids, _ = cube_ids(RF, lo, width)
        uniq, inv, counts = np.unique(ids, return_inverse=True, return_counts=True)
        fitness = 10.0 / counts
        cubes = rng.choice(len(uniq), size=n, p=fitness / fitness.sum())
        leaders = np.array([rng.choice(np.flatnonzero(inv == k)) for k in cubes])
        r1, r2 = rng.random((n, d)), rng.random((n, d))
        V = w * V + r1 * (PB - X) + r2 * (RX[leaders] - X)
        X = X + V
        out = (X < 0) | (X > 1)
        X = np.clip(X, 0, 1)
        V = np.where(out, -V, V)
        if t < T * p_m:
            s = (1 - t / (T * p_m)) ** 1.5
            for i in np.flatnonzero(rng.random(n) < s):
                j = rng.integers(d)
                X[i, j] = rng.uniform(max(X[i, j] - s / 2, 0), min(X[i, j] + s / 2, 1))
        F = _zdt1(X)
        for i in range(n):
            RX, RF = insert(X[i], F[i], RX, RF)
        take = dominates(F, PF) | (~dominates(PF, F) & (rng.random(n) < 0.5))
        PB[take], PF[take] = X[take], F[take]
    return RF


def test_mopso_zdt1_median_igd_matches_a_sequential_reference():
    ours = mopso_igd()
    ref = float(np.median([igd(reference_mopso(s)) for s in SEEDS]))
    print(f"MOPSO ZDT1 median IGD: dockjax {ours:.4f}, sequential reference {ref:.4f}")
    assert 0.6 * ref <= ours <= 1.5 * ref


@pytest.mark.xfail(
    strict=True,
    reason="Coello et al.'s MOPSO (w = 0.4, c1 = c2 = 1, clamp-and-reverse) converges slowly "
    "on 30-variable ZDT1: at 100 x 100 evaluations its median IGD is ~0.5 (the sequential "
    "reference agrees) against ~0.016 for pymoo's NSGA-II; it reaches ~0.02 after 1000 "
    "iterations.",
)
def test_mopso_zdt1_median_igd_within_3x_pymoo_nsga2(pymoo_zdt1_igd):
    assert mopso_igd() <= 3.0 * pymoo_zdt1_igd


def test_mopso_same_key_gives_bit_identical_runs():
    first, again = mopso_runs()
    for a, b in zip(jax.tree_util.tree_leaves(first), jax.tree_util.tree_leaves(again)):
        np.testing.assert_array_equal(a, b)


def test_mopso_repository_holds_only_mutually_nondominated_members():
    state, _ = mopso_runs()
    for i in range(len(SEEDS)):
        valid = state.archive_valid[i]
        F, cv = state.repository.F[i], state.repository.cv[i]
        assert valid.sum() >= 1
        members = F[valid]
        assert len(first_front(members)) == len(members)
        assert len(np.unique(members, axis=0)) == len(members)
        assert np.all(cv[valid] == 0) and np.all(np.isinf(cv[~valid]))
        # Nothing the swarm found at the end dominates a repository member.
        cur = state.pop.F[i]
        dom = np.all(cur[:, None] <= members[None], -1) & np.any(cur[:, None] < members[None], -1)
        assert not dom.any()
    assert np.all(state.iteration == ITERS)
    # final_population is the repository.
    with jax.enable_x64(True):
        one = jax.tree_util.tree_map(lambda a: a[0], state)
        np.testing.assert_array_equal(mopso.final_population(one).F, state.repository.F[0])
