"""Splines of any number of free control points (``DockingProblem(n_control=n)``, n = 1..64).

Every check is against the independent reference of ``tests/reference.py`` (a SciPy
``BSpline`` of the same knots and control points, Gauss–Legendre jerk integrals, dense
sampling of the limits): objectives to 1e-9 relative, limit columns never below the dense
maximum and at most 0.01 above it (conventions §6), in every right-arm treatment, screened
or not, and for the plans, optimisers and studies built on the kernel.
"""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from dockjax import DockingProblem, cli
from dockjax.optimize import optimize
from dockjax.plan import plan
from tests import reference as R
from tests.test_right_arm_certified import _check, _problems, _scaled, _travel, dense_bracket

ROWS = 4


def _reference(p: DockingProblem, X):
    """The reference's F (rows, 2) and dense-sampled G (rows, 24) of the rows of X."""
    lim = np.asarray(p.limits)
    F = np.array([R.reference_objectives(x, p.start, p.goal, p.arm_distance) for x in X])
    G = np.array([R.dense_constraints(x, p.start, p.goal, p.arm_distance, lim[:, 0], lim[:, 1], lim[:, 2],
                                      home=p.home, n_samples=10001) for x in X])
    return F, G


def _reference_check(p: DockingProblem, X, F, G, reference=None):
    """F to 1e-9 relative and every G column in [dense − 1e-9, dense + 0.01] (reference only)."""
    F_ref, dense = _reference(p, X) if reference is None else reference
    for i in range(len(X)):
        np.testing.assert_allclose(F[i], F_ref[i], rtol=1e-9, err_msg=f"F of row {i}")
        assert np.all(G[i] >= dense[i] - 1e-9), (i, np.min(G[i] - dense[i]))
        assert np.all(G[i] <= dense[i] + 0.01), (i, np.max(G[i] - dense[i]))


@pytest.mark.parametrize("n", [1, 64])
def test_scores_of_any_family_match_the_reference(n):
    """Random candidates of the box and near-limit ones (a row's intervals scaled so that its
    largest rate column sits at its limit) of a spline with n free control points."""
    p = DockingProblem(n_control=n, interval_bounds=(0.5, 10.0))
    assert p.n_var == 7 * n + 1 and p.n_intervals == n + 1
    assert (p.lower.shape, p.upper.shape) == ((7 * n + 1,), (7 * n + 1,))
    rng = np.random.default_rng(n)
    X = rng.uniform(p.lower, p.upper, (ROWS, p.n_var))
    # row 3: row 0 slowed so that its worst velocity or acceleration column is at its limit
    m = R.dense_quantity_maxima(X[0], p.start, p.goal, p.arm_distance, home=p.home, n_samples=4001) / p.limits
    X[3] = _scaled(X[0], max(m[:, 1].max(), np.sqrt(m[:, 2].max())))
    X[3, : p.n_intervals] = np.minimum(X[3, : p.n_intervals], 1e3)
    reference = _reference(p, X)
    for screen in (True, False):
        F, G = p.evaluate(X, screen=screen)
        assert F.shape == (ROWS, 2) and G.shape == (ROWS, 24)
        _reference_check(p, X, F, G, reference)


def test_decoded_trajectory_is_the_reference_spline():
    p = DockingProblem(n_control=7)
    x = np.random.default_rng(7).uniform(p.lower, p.upper)
    tr = p.decode(x)
    assert tr.knots.shape == (19,) and tr.control_points.shape == (13, 6)
    t = np.linspace(0.0, tr.T, 301)
    ref = R.pose_spline(x, p.start, p.goal)
    np.testing.assert_allclose(tr.pose(t), ref(t), rtol=0, atol=1e-9)
    np.testing.assert_allclose(tr.knots, R.knots(x[:8]), rtol=1e-15, atol=0)


def test_reduced_family_puts_the_points_on_the_line():
    p = DockingProblem(n_control=9, reduced=True)
    assert p.n_var == 10
    h = np.random.default_rng(9).uniform(p.lower, p.upper, (ROWS, 10))
    F, G = p.evaluate(h)
    full = np.array([R.reduced_to_full(row, p.start, p.goal) for row in h])
    _reference_check(p, full, F, G)


@given(
    move=st.tuples(st.floats(-100, 100), st.floats(-100, 100), st.floats(-300, 300), st.floats(-30, 30),
                   st.floats(-30, 30), st.floats(-10, 10)),
    log_lo=st.floats(-1.0, 2.0),
    ratio=st.floats(1.2, 10.0),
    seed=st.integers(0, 2**32 - 1),
    joint=st.sampled_from([4, 5, 6]),
)
# a row slowed by 2e-4 (so sped up 5000×) lies millions of limits over: rounding at that scale
@example(move=(-22.0, 0.0, 0.125, 0.0, 0.0, 0.0), log_lo=0.0, ratio=4.919654192287588, seed=3834461, joint=4)
def test_right_arm_columns_of_other_families_are_certified_in_every_mode(move, log_lo, ratio, seed, joint):
    """Attitude moves of tens of degrees with 2 free control points: the right arm's
    treatments (``"auto"``, which is ``"bound"`` or ``"adaptive"`` by the move, and
    ``"taylor"``), screened or not, never below the dense bracket and (but ``"bound"``)
    within 0.01 of the limit above it.

    The problems carry jerk limits too high to bind, with the jerk node count of
    ``tests/test_jerk_limits.py``: its kernels are these, compiled once for both files
    (the jerk columns are that file's to check)."""
    start = (760.0, -20.0, -1400.0, 5.0, -3.0, 185.0)
    goal = tuple(float(a + b) for a, b in zip(start, move))
    lo = float(10.0 ** log_lo)
    travel = _travel(start, goal, 2000.0, 1.2)
    p_auto, problems = _problems(start, goal, 2000.0, (lo, lo * ratio), travel, n_control=2, jerk=(1e12,) * 4)
    problems = {"taylor": problems["taylor"]}  # "auto" is "bound" or "adaptive" by the move
    x, y = np.random.default_rng(seed).uniform(p_auto.lower, p_auto.upper, (2, p_auto.n_var))
    lower, _ = dense_bracket(p_auto, x)
    # near-limit rows: x slowed (velocity ∝ 1/s, acceleration ∝ 1/s²) to put one right-arm
    # velocity and one acceleration column at their limits
    s_v, s_a = lower[3 * joint + 1] + 1.0, np.sqrt(max(lower[3 * joint + 2] + 1.0, 0.0))
    X = np.stack([x, y] + [_scaled(x, s) if s > 1e-12 else y for s in (s_v, s_a)])
    _check(p_auto, problems, X, f"n_control=2, goal={goal}, interval_bounds={(lo, lo * ratio)}")


@pytest.mark.parametrize("value", [0, 65, 2.5, "5", None])
def test_bad_n_control_is_refused_naming_it(value):
    with pytest.raises(ValueError, match="n_control must be an integer from 1 to 64"):
        DockingProblem(n_control=value)


def test_one_family_compiles_once_and_problems_of_two_families_differ():
    a, b = DockingProblem(n_control=2), DockingProblem(n_control=3)
    assert a.identity() != b.identity() and "n_control" in a.identity()
    assert "n_control" not in DockingProblem().identity()  # the paper's family keeps its identity
    assert "n_control=2" in repr(a) and "n_control" not in repr(DockingProblem())


@pytest.mark.parametrize("algorithm", ["nsga2", "mopso", "mocs", "imocs"])
def test_every_optimiser_runs_on_another_family_and_its_feasible_points_are_certified(algorithm):
    """The host driver: the four runs share one compiled kernel call and each compiles only
    its small ask/tell programs (the scan driver's agreement with it is checked on ZDT1,
    tests/test_nsga2_mopso.py)."""
    p = DockingProblem(n_control=2)
    res = optimize(algorithm, p, pop_size=8, n_iter=4, seeds=[0], driver="host")
    assert res.X.shape == (1, 8, 15)
    X, G = np.asarray(res.X[0]), np.asarray(res.G[0])
    assert np.all(X >= p.lower - 1e-12) and np.all(X <= p.upper + 1e-12)
    ok = np.all(G <= 0, 1)
    if ok.any():
        dense, feasible = R.dense_check(p, X[ok], n_samples=4001)
        assert feasible.all(), dense.max()


def test_a_plan_with_two_control_points_is_certified_by_the_reference():
    p = DockingProblem(n_control=2, interval_bounds=(1.0, 10.0))
    result = plan(p, rate=20.0, n_front=2, weights=(1.0, 0.0), check_sensitivities=False)
    assert result.x.shape == (15,)
    _, feasible = R.dense_check(p, result.x[None], n_samples=20001)
    assert feasible.all()
    T, jerk = R.reference_objectives(result.x, p.start, p.goal, p.arm_distance)
    assert result.T == pytest.approx(T, rel=1e-9) and result.jerk == pytest.approx(jerk, rel=1e-9)


def test_a_plan_with_more_points_than_the_papers_starts_from_its_plan_and_is_certified():
    """Six free control points: the shortest time starts from the paper family's shortest
    plan written exactly in the finer family, so it is certified by the reference and takes
    at most the paper family's plan's time, but for the least-jerk slack of each family's
    shortest plan (``solve.SHORTEST_SLACK``, twice) and the finer spans' certificate."""
    from dockjax import solve

    options = dict(rate=20.0, n_front=2, weights=(1.0, 0.0), check_sensitivities=False)
    paper = plan(DockingProblem(interval_bounds=(1.0, 10.0)), **options)
    p = DockingProblem(n_control=6, interval_bounds=(1.0, 10.0))
    result = plan(p, **options)
    assert result.x.shape == (43,)
    _, feasible = R.dense_check(p, result.x[None], n_samples=20001)
    assert feasible.all()
    T, jerk = R.reference_objectives(result.x, p.start, p.goal, p.arm_distance)
    assert result.T == pytest.approx(T, rel=1e-9) and result.jerk == pytest.approx(jerk, rel=1e-9)
    T_paper, _ = R.reference_objectives(paper.x, p.start, p.goal, p.arm_distance)
    assert T <= T_paper * (1 + solve.SHORTEST_SLACK) ** 2 * (1 + 1e-6)


def _main(argv):
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        code = cli.main(argv)
    return code, text.getvalue()


def test_plan_command_takes_n_control_and_records_it(tmp_path):
    out = tmp_path / "plan"
    code, _ = _main(["plan", "--n-control", "2", "--interval-bounds", "1", "10", "--n-front", "2",
                     "--select", "time", "--rate", "20", "--out", str(out)])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["n_control"] == 2 and len(summary["x"]) == 15


@pytest.mark.parametrize("argv", [["plan", "--n-control", "0"], ["plan", "--n-control", "65"],
                                  ["sweep", "--n-control", "0"], ["compare", "--n-control", "99"]])
def test_commands_refuse_a_bad_n_control_with_one_line(tmp_path, capsys, argv):
    code, _ = _main([*argv, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "--n-control" in err and "from 1 to 64" in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_a_study_records_its_family_and_refuses_another():
    from dockjax.sweep import make_config, paper_config
    from dockjax.sweep.config import SweepConfig

    cfg, _ = make_config(pop=(8,), iters=(2,), seeds=2, n_control=3)
    assert cfg.identity()["n_control"] == 3
    assert SweepConfig.from_identity(cfg.identity()).n_control == 3
    assert "n_control" not in make_config(pop=(8,), iters=(2,), seeds=2)[0].identity()
    assert paper_config(seeds=2, pop=8, iters=2, n_control=3).n_control == 3


def test_knot_insertion_matches_scipys_insert():
    """Boehm's insertion against SciPy's FITPACK ``insert``, coordinate by coordinate."""
    from scipy.interpolate import insert

    from dockjax.bspline import insert_knots

    rng = np.random.default_rng(3)
    u = R.knots(rng.uniform(0.5, 2.0, 6))
    ctrl = rng.normal(size=(11, 2))
    new = np.sort(rng.uniform(u[0], u[-1], 4))
    u2, c2 = insert_knots(u, ctrl, new)
    for d in range(2):
        t, c, _ = u, np.r_[ctrl[:, d], np.zeros(6)], 5  # FITPACK pads c to len(t)
        for v in new:
            t, c, _ = insert(v, (t, c, 5))
        np.testing.assert_allclose(u2, t, rtol=0, atol=1e-12)
        np.testing.assert_allclose(c2[:, d], c[: len(u2) - 6], rtol=0, atol=1e-12)


def test_a_trajectory_carried_to_a_finer_family_keeps_its_scores():
    from dockjax.solve import refine_family

    coarse = DockingProblem(interval_bounds=(0.1, 10.0))
    fine = coarse.with_n_control(64)
    assert fine.n_control == 64 and fine.interval_bounds == coarse.interval_bounds
    x = np.random.default_rng(5).uniform(coarse.lower, coarse.upper)
    y = refine_family(fine, coarse, x)
    assert y.shape == (fine.n_var,) and np.all(y >= fine.lower) and np.all(y <= fine.upper)
    t = np.linspace(0.0, x[:6].sum(), 501)
    np.testing.assert_allclose(R.pose_spline(y, fine.start, fine.goal)(t), R.pose_spline(x, coarse.start,
                               coarse.goal)(t), rtol=0, atol=1e-9)
    (F1, G1), (F2, G2) = coarse.evaluate(x[None], screen=False), fine.evaluate(y[None], screen=False)
    np.testing.assert_allclose(F2, F1, rtol=1e-9)
    linear = np.r_[0:12, 21:24]  # the joints linear in the pose: exact columns in both families
    np.testing.assert_allclose(G2[:, linear], G1[:, linear], rtol=0, atol=1e-9)
    _reference_check(fine, y[None], F2, G2)  # the right arm's: certified bounds in both
    _reference_check(coarse, x[None], F1, G1)
    assert refine_family(coarse, fine, y) is None  # no family with fewer points


def test_values_come_without_the_jacobian_and_a_large_programme_solves_alike(monkeypatch):
    """SLSQP asks for values (objective, gradient, constraints) and the constraints' Jacobian
    from two compiled programmes: the values are those of the programme with the Jacobian
    (objective and gradient bit for bit, constraints to rounding). A programme with more
    candidate constraints than ``solve.DENSE_CONSTRAINTS`` keeps its near-active ones; that
    path, forced here on a small family, reaches a certified shortest time within 1e-6 of
    the path with every constraint."""
    import jax

    from dockjax import solve

    p = DockingProblem(n_control=2, interval_bounds=(1.0, 10.0))
    u = np.random.default_rng(0).uniform(0.0, 1.0, p.n_var)
    with jax.enable_x64(True):
        # scale and weight as solve passes them (np.float64: the programmes the solves below compile)
        scale, weight = np.float64(10.0), np.float64(0.5)
        f, fg, g = (np.asarray(a) for a in solve._primal_values(p, u, scale, weight))
        F, FG, G, _ = (np.asarray(a) for a in solve._values(p, u, scale, weight))
    assert f == F and np.array_equal(fg, FG)
    np.testing.assert_allclose(g, G, rtol=1e-12, atol=1e-12)

    x0 = solve.straight_line(p, [30.0])[0]
    one = solve.min_time(p, x0)
    monkeypatch.setattr(solve, "DENSE_CONSTRAINTS", 0)
    two = solve.min_time(p, x0)
    _, feasible = R.dense_check(p, two.x[None], n_samples=20001)
    assert feasible.all()
    T_ref, _ = R.reference_objectives(two.x, p.start, p.goal, p.arm_distance)
    assert two.F[0] == pytest.approx(T_ref, rel=1e-9)
    assert two.F[0] == pytest.approx(one.F[0], rel=1e-6)
