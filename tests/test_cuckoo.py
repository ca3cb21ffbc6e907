"""IMOCS and MOCS: operators, chaotic initialisation, runs on ZDT1 and on the docking problem."""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest
from scipy.stats import qmc

from dockjax import DockingProblem
from dockjax.algorithms.operators import (
    bernoulli_map,
    bernoulli_population,
    levy_step,
    mantegna_sigma,
    random_rank1_partner,
)
from dockjax.algorithms.zdt import ZDT1
from dockjax.optimize import optimize
from tests import reference as R
from tests.conftest import SHORT_IMOCS, short_imocs_runs


def _igd(F, front):
    return float(np.sqrt(((front[:, None, :] - F[None]) ** 2).sum(-1)).min(1).mean())


def test_mantegna_sigma_matches_the_closed_form_at_beta_1_5():
    beta = 1.5
    expect = (math.gamma(2.5) * math.sin(math.pi * 0.75) / (math.gamma(1.25) * 1.5 * 2**0.25)) ** (1 / 1.5)
    assert mantegna_sigma(beta) == pytest.approx(expect, rel=1e-15)
    assert mantegna_sigma(beta) == pytest.approx(0.6966, abs=1e-4)


def test_levy_steps_have_the_mantegna_scale():
    with jax.enable_x64(True):
        s = np.asarray(levy_step(jax.random.key(0), (200_000,), np.float64))
    assert s.dtype == np.float64 and np.all(np.isfinite(s))
    # median of |u|/|v|^(2/3): compare with a numpy simulation of the same law
    rng = np.random.default_rng(1)
    ref = mantegna_sigma() * rng.normal(size=200_000) / np.abs(rng.normal(size=200_000)) ** (1 / 1.5)
    assert np.median(np.abs(s)) == pytest.approx(np.median(np.abs(ref)), rel=0.02)


def test_rank1_partner_is_uniform_over_the_rank1_set():
    """conventions §7: x_j drawn at random from the current rank-1 set: never another member, and
    each rank-1 member about equally often (chi-square, 50 draws per member and nest set)."""
    from scipy.stats import chisquare

    rank = np.array([1, 0, 2, 0, 0, 3, 1, 0, 0, 2] * 3)
    keys = jax.random.split(jax.random.PRNGKey(0), 200)
    with jax.enable_x64(True):
        got = np.asarray(jax.jit(jax.vmap(random_rank1_partner, in_axes=(0, None)))(keys, rank))
    assert np.all(rank[got] == 0)
    counts = np.bincount(got.ravel(), minlength=len(rank))[rank == 0]
    assert chisquare(counts).pvalue > 1e-3


def test_bernoulli_map_is_paper_eq_31():
    z = np.array([0.1, 0.6, 0.59, 0.61, 0.9])
    rho = 0.4
    expect = np.where(z <= 0.6, z / 0.6, (z - 0.6) / 0.4)
    with jax.enable_x64(True):
        np.testing.assert_allclose(np.asarray(bernoulli_map(z, rho)), expect, rtol=1e-15)


@pytest.mark.parametrize("rho", [0.5, 0.4])
def test_chaotic_initialisation_gives_distinct_well_spread_nests(rho):
    with jax.enable_x64(True):
        U = np.asarray(bernoulli_population(jax.random.key(3), 2000, 36, rho))
    assert U.shape == (2000, 36)
    assert len(np.unique(U, axis=0)) == 2000  # n distinct nests
    assert U.min() > 0.0 and U.max() < 1.0  # no collapse to the fixed points
    # no dimension collapsed: every dimension still fills all 20 bins of [0, 1]
    counts = np.stack([np.histogram(U[:, j], bins=20, range=(0, 1))[0] for j in range(36)])
    assert counts.min() >= 40  # uniform would give 100 per bin
    # not worse spread than uniform random: centred L2 discrepancy over 5 seeds (n = 150)
    with jax.enable_x64(True):
        chaotic = [qmc.discrepancy(np.asarray(bernoulli_population(jax.random.key(s), 150, 36, rho))) for s in range(5)]
    uniform = [qmc.discrepancy(np.random.default_rng(s).uniform(size=(150, 36))) for s in range(5)]
    assert np.median(chaotic) <= 1.02 * np.median(uniform)


def test_bad_hyper_parameters_raise_before_compiling():
    z = ZDT1()
    with pytest.raises(ValueError, match="rho"):
        optimize("imocs", z, rho=1.0, pop_size=10, n_iter=2)
    with pytest.raises(ValueError, match="rho"):
        optimize("imocs", z, rho=0.0, pop_size=10, n_iter=2)
    with pytest.raises(ValueError, match="alpha_max"):
        optimize("imocs", z, alpha_max=0.0, pop_size=10, n_iter=2)
    with pytest.raises(ValueError, match="p_a"):
        optimize("mocs", z, p_a=1.5, pop_size=10, n_iter=2)
    with pytest.raises(ValueError, match="pop_size"):
        optimize("imocs", z, pop_size=3, n_iter=2)
    with pytest.raises(ValueError, match="n_iter"):
        optimize("imocs", z, pop_size=10, n_iter=0)
    with pytest.raises(ValueError, match="algorithm"):
        optimize("cuckoo", z)
    with pytest.raises(ValueError, match="unknown hyper-parameter"):
        optimize("mocs", z, rho=0.4, pop_size=10, n_iter=2)
    with pytest.raises(ValueError, match="driver"):
        optimize("mocs", z, pop_size=10, n_iter=2, driver="loop")




@pytest.mark.parametrize("name", ["imocs", "mocs"])
def test_cuckoo_searches_reach_the_zdt1_front(name, pymoo_zdt1_igd):
    """Median IGD over 5 seeds (population 100, 100 iterations, equal budgets).

    The conventions' step factor (α₀ = 0.01) and discovery rate make the cuckoo searches
    slower on ZDT1 than SBX: IMOCS ends at about 3×, MOCS at about 4.4× pymoo's NSGA-II
    (≈ 0.016). The test pins that level (≤ 5×) and that the runs do converge (far below a
    random population's IGD).
    """
    front = ZDT1.pareto_front()
    r = optimize(name, ZDT1(), seeds=range(5), pop_size=100, n_iter=100)
    igd = np.median([_igd(F, front) for F in r.F])
    rng = np.random.default_rng(0)
    random_igd = _igd(ZDT1().evaluate(rng.uniform(size=(100, 30)))[0], front)
    assert igd < 0.05 * random_igd
    assert igd <= 5.0 * pymoo_zdt1_igd


@pytest.fixture(scope="module")
def docking_runs():
    p = DockingProblem()
    return p, short_imocs_runs(p)  # the program of the README's snippet and the sweeps


def test_docking_final_feasible_sets_pass_the_dense_check(docking_runs):
    p, r = docking_runs
    for i in range(len(r)):
        for x in r.X[i][r.feasible[i]][:6]:
            g = R.dense_constraints(x, p.start, p.goal, p.arm_distance, p.limits[:4, 0],
                                    p.limits[:4, 1], p.limits[:4, 2])
            assert np.all(g <= 0)


def test_same_key_gives_bit_identical_runs_and_batching_does_not_change_them(docking_runs):
    p, r = docking_runs
    again = short_imocs_runs(p)
    np.testing.assert_array_equal(r.F, again.F)
    np.testing.assert_array_equal(r.X, again.X)
    # each run alone, with its own hyper-parameters as plain numbers
    single = [optimize("imocs", p, seeds=[s], pop_size=8, n_iter=3, rho=SHORT_IMOCS["rho"][s],
                       alpha_max=SHORT_IMOCS["alpha_max"][s]) for s in (0, 1)]
    from dockjax.metrics import hypervolume_2d

    ref = np.array([65.0, 20.0])
    with jax.enable_x64(True):
        hv = lambda F, m: float(hypervolume_2d(F, m, ref))  # noqa: E731
        for s, one in zip((0, 1), single):
            batched, alone = hv(r.F[s], r.feasible[s]), hv(one.F[0], one.feasible[0])
            assert batched == pytest.approx(alone, rel=0.01)


def test_per_run_hyper_parameters_vary_the_runs_and_are_kept_in_the_result():
    from dockjax.algorithms import imocs

    r = optimize("imocs", ZDT1(), seeds=[0, 0], pop_size=20, n_iter=5, rho=[0.3, 0.7])
    assert not np.array_equal(r.U[0], r.U[1])  # ρ changes the chaotic start
    assert r.params_of(1) == imocs.Params(pop_size=20, max_iter=5, rho=0.7)
    np.testing.assert_array_equal(r.params.alpha_max, [0.1, 0.1])
    # the same runs from a Params pytree whose leaf carries the run axis
    params = imocs.Params(pop_size=20, max_iter=5, rho=np.array([0.3, 0.3]))
    same = optimize("imocs", ZDT1(), params=params, seeds=[0, 0])
    np.testing.assert_array_equal(same.U[0], same.U[1])
    np.testing.assert_array_equal(same.U[0], r.U[0])
    with pytest.raises(ValueError, match="one per seed"):
        optimize("imocs", ZDT1(), params=params, seeds=[0, 1, 2])
