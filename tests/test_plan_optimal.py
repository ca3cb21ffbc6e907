"""Plans that are optimal, fast and explained (dockjax.solve, dockjax.plan).

References written here, independent of the code under test: the per-joint bang-bang floor
(a lower bound of any trajectory's time), SciPy SLSQP on the test's own B-spline
(:mod:`reference`, SciPy's BSpline) with constraints at dense fixed sample times and
finite-difference gradients, gradient refinement (:mod:`dockjax.refine`, another
algorithm) from several starts, and the dense check of every limit.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.optimize import OptimizeResult, minimize

from dockjax import plan as P
from dockjax import solve
from dockjax.best_known import best_known_front
from dockjax.plan import Planner, plan
from dockjax.problem import DockingProblem, make_problem
from dockjax.refine import refine
from tests import reference as R

WIDE = make_problem("wide")


def _floor(problem) -> float:
    """The shortest time any trajectory can take: per joint, the bang-bang profile with the
    velocity and acceleration limits (triangular when the move is short), the largest."""
    q0 = R.joints_of_pose(problem.start, problem.arm_distance)
    q1 = R.joints_of_pose(problem.goal, problem.arm_distance)
    d = np.abs(q1 - q0)
    v, a = problem.limits[:, 1], problem.limits[:, 2]
    t = np.where(d >= v * v / a, d / v + v / a, 2 * np.sqrt(d / a))
    return float(t.max())


def _sampled_g(problem, x, per_span=40):
    """|v|/v_lim − 1 and |a|/a_lim − 1 and travel at fixed fractions of each span (the
    reference spline), all joints: a smooth function of x."""
    h = x[:6]
    edges = np.concatenate([[0.0], np.cumsum(h)])
    frac = np.linspace(0.0, 1.0, per_span)
    t = (edges[:-1, None] + frac * h[:, None]).ravel()
    t = np.clip(t, 0.0, edges[-1] * (1 - 1e-15))
    qd = R.joint_derivatives(x, problem.start, problem.goal, problem.arm_distance, t)
    lim = problem.limits
    return np.concatenate([((qd[0] - problem.home) / lim[:, 0]).ravel() ** 2 - 1,
                           (qd[1] / lim[:, 1]).ravel() ** 2 - 1, (qd[2] / lim[:, 2]).ravel() ** 2 - 1])


def _reference_min_time(problem, x0):
    """SciPy SLSQP, finite-difference gradients, on the reference spline's sampled limits."""
    lo, hi = problem.lower, problem.upper
    w = hi - lo
    res = minimize(lambda u: np.sum((lo + u * w)[:6]), (x0 - lo) / w, method="SLSQP", bounds=[(0, 1)] * len(lo),
                   constraints=[{"type": "ineq", "fun": lambda u: -_sampled_g(problem, lo + u * w)}],
                   options={"maxiter": 300, "ftol": 1e-10})
    return lo + res.x * w


def _summary(wide_time_plan) -> dict:
    """The wide preset's shortest-time plan (``dockjax plan --select time``), as written."""
    folder, _ = wide_time_plan
    s = json.loads((folder / "summary.json").read_text())
    s["x"] = np.array(s["x"])
    return s


def test_shortest_time_is_above_the_floor_dense_feasible_and_no_worse_than_an_independent_solver(wide_time_plan):
    p = _summary(wide_time_plan)
    T, x = p["T_s"], p["x"]
    assert T == pytest.approx(p["settings"]["shortest_T_s"], rel=1e-12) and T == pytest.approx(np.sum(x[:6]))
    assert T >= _floor(WIDE) - 1e-9
    _, ok = R.dense_check(WIDE, x[None], n_samples=40001)
    assert ok.all()
    x_ref = _reference_min_time(WIDE, R.straight_line_x(WIDE.start, WIDE.goal, (2.5,) * 6))
    T_ref = float(np.sum(x_ref[:6]))
    g_ref = R.dense_constraints(x_ref, WIDE.start, WIDE.goal, WIDE.arm_distance, WIDE.limits[:, 0],
                                WIDE.limits[:, 1], WIDE.limits[:, 2], n_samples=40001)
    T_ref_feasible = T_ref * max(1.0, np.sqrt(g_ref.reshape(8, 3)[:, 2].max() + 1), g_ref.reshape(8, 3)[:, 1].max() + 1)
    assert T <= T_ref_feasible * (1 + 1e-3), (T, T_ref, T_ref_feasible)
    # and the printed peers' floor: 30 mm of lateral travel at 2.5 mm/s and 100 mm/s²
    assert _floor(WIDE) == pytest.approx(12.025, abs=1e-9)


def _coverage_floor(d, v, a) -> float:
    """The least T in which a rest-to-rest motion within |v|, |a| covers d, by bisection
    on the farthest distance such a motion covers in T (v (T − v/a) once it reaches v,
    else a T²/4): the bang-bang floor derived the other way round."""
    reach = lambda T: v * (T - v / a) if T >= 2 * v / a else a * T * T / 4  # noqa: E731
    lo, hi = 0.0, 1.0
    while reach(hi) < d:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if reach(mid) < d else (lo, mid)
    return hi


FLOOR_CASES = st.fixed_dictionaries(dict(
    velocity=st.lists(st.floats(0.05, 50.0), min_size=4, max_size=4),
    acceleration=st.lists(st.floats(0.01, 100.0), min_size=4, max_size=4),
    move=st.lists(st.floats(-40.0, 40.0), min_size=3, max_size=3),
    attitude=st.lists(st.floats(-0.5, 0.5), min_size=2, max_size=2),
    roll=st.floats(-5.0, 5.0),
))


@settings(max_examples=15, deadline=None)
@given(FLOOR_CASES)
@example(case=dict(velocity=[1.0] * 4, acceleration=[1.0] * 4, move=[0.0] * 3, attitude=[0.0, -5.960464477539063e-08],
                   roll=0.0))  # a move of 7e-9 °, as small as the joint values' rounding
def test_the_time_floor_is_each_joints_bang_bang_time_and_below_every_certified_trajectory(case):
    """``solve.time_floor`` against the floor found the other way round (the least T whose
    farthest rest-to-rest reach covers the joint's move, reference kinematics), and never
    above the time of a trajectory the kernel certifies (the straight line slowed until
    every column is within its limit)."""
    start = np.array(WIDE.start, float)
    goal = start + np.array([*case["move"], *case["attitude"], case["roll"]])
    kw = dict(start=start, goal=goal, velocity=case["velocity"], acceleration=case["acceleration"],
              travel=[200.0, 200.0, 200.0, 200.0], interval_bounds=(0.5, 1e4))
    p = DockingProblem(**kw)
    q0, q1 = R.joints_of_pose(p.start, p.arm_distance), R.joints_of_pose(p.goal, p.arm_distance)
    lim = np.asarray(p.limits)
    ref = [_coverage_floor(abs(b - a), v, acc) for a, b, v, acc in zip(q0, q1, lim[:, 1], lim[:, 2])]
    # the joint values carry rounding (a few units of eps·|q| here and in the library): the
    # floor may lie below the reference by what 128 such units of the move are worth, never above it
    slack = 128 * np.finfo(float).eps * np.maximum(np.maximum(np.abs(q0), np.abs(q1)), 1.0)
    low = [_coverage_floor(max(abs(b - a) - e, 0.0), v, acc)
           for a, b, e, v, acc in zip(q0, q1, slack, lim[:, 1], lim[:, 2])]
    floor = solve.time_floor(p)
    assert np.all(floor <= np.array(ref) * (1 + 1e-9) + 1e-12), (floor, ref)
    assert np.all(floor >= np.array(low) * (1 - 1e-9) - 1e-12), (floor, low)
    x = solve.straight_line(p, [1.0])[0]
    for _ in range(10):  # the right arm's columns scale with time only approximately
        _, G = p.evaluate(x[None], screen=False)
        if np.all(G <= 0):
            break
        x = solve.time_scale(p, x, solve.scaling_need(G)[0] * (1 + 1e-6))
    assert np.all(G <= 0) and np.sum(x[: p.n_intervals]) >= max(ref) * (1 - 1e-12)


@pytest.mark.parametrize("limits, kind", [(dict(velocity=[400, 25, 0.4, 6.8]), "velocity"),
                                          (dict(acceleration=[100, 100, 1e-3, 100]), "acceleration")])
def test_a_move_beyond_the_floor_fails_at_once_naming_its_limit(limits, kind, monkeypatch):
    """A lateral move of 30 mm that no trajectory makes within the longest T = 60 s: the
    PlanError names d_L3 and the limit, with the excess of the least peak that would cover
    the move in 60 s (reference: the roots of the trapezoid's v² / a − v T + d = 0, or the
    triangle's 4 d / T²), and no SQP runs."""
    monkeypatch.setattr(solve, "_slsqp", lambda *a, **k: pytest.fail("an SQP ran"))
    p = DockingProblem(**limits)
    with pytest.raises(solve.PlanError) as info:
        plan(p, check_sensitivities=False)
    e, T, d = info.value, 60.0, 30.0
    v, a = np.asarray(p.limits)[2, 1:3]
    peak = {"velocity": min(np.roots([1 / a, -T, d]).real) / v, "acceleration": 4 * d / T**2 / a}[kind]
    assert (e.joint, e.quantity, e.limit) == ("d_L3", kind, dict(velocity=v, acceleration=a)[kind])
    assert e.excess == pytest.approx(peak - 1, rel=1e-9) and e.excess > 0 and "30 mm" in str(e)
    with pytest.raises(solve.PlanError):
        best_known_front(p, n_points=4, n_exact=2)


@pytest.mark.parametrize("preset", ["wide", "paper"])
def test_the_chosen_plan_has_the_least_jerk_at_its_time_within_0_1_percent(preset, request):
    if preset == "wide":  # plan(make_problem("wide"), weights=(1, 1))
        problem, p = WIDE, request.getfixturevalue("wide_compromise_plan")
        x, T, jerk = p.x, p.T, p.jerk
    else:  # dockjax plan with its defaults: the paper's move, weights (1, 1)
        problem, s = make_problem("paper"), json.loads((request.getfixturevalue("paper_plan") / "summary.json")
                                                         .read_text())
        x, T, jerk = np.array(s["x"]), s["T_s"], s["jerk"]
    _, ok = R.dense_check(problem, x[None], n_samples=40001)
    assert ok.all()
    # another algorithm from several starts: projected Adam under T <= T_plan
    starts = [R.straight_line_x(problem.start, problem.goal, (T / 6,) * 6)]
    rng = np.random.default_rng(0)
    for _ in range(3):
        d = rng.uniform(-0.03, 0.03, 6)
        h = T / 6 * (1 + d - d.mean())  # inside the box for both presets' T here
        xs = R.straight_line_x(problem.start, problem.goal, h)
        xs[6:] += rng.uniform(-0.02, 0.02, xs.size - 6) * (problem.upper - problem.lower)[6:]
        starts.append(np.clip(xs, problem.lower, problem.upper))
    # in one call of the four rows (the paper's, 16 rows, is the compiled call of the studies')
    r = refine(problem, np.array(starts), steps=1500, rows=4 if preset == "wide" else None)
    best = r.F[r.feasible & (r.F[:, 0] <= T * (1 + 1e-12)), 1]
    assert best.size
    for xr in r.X[r.feasible]:
        assert R.reference_objectives(xr, problem.start, problem.goal, problem.arm_distance)[0] <= T * (1 + 1e-9)
    T_p, J_p = R.reference_objectives(x, problem.start, problem.goal, problem.arm_distance)
    assert T_p == pytest.approx(T, rel=1e-12) and J_p == pytest.approx(jerk, rel=1e-8)
    assert J_p <= best.min() * (1 + 1e-3), (J_p, best.min())


def test_sensitivities_match_replanning_with_the_limit_changed_by_one_percent(wide_time_plan,
                                                                           wide_compromise_plan):
    rows = _summary(wide_time_plan)["explanation"]["binding"]
    assert rows, "the shortest time binds at least one limit"
    for row in rows:
        j = ["d_L1", "d_L2", "d_L3", "theta_L", "d_R1", "d_R2", "d_R3", "theta_R"].index(row["joint"])
        key = row["quantity"]
        T = []
        for f in (1.01, 0.99):
            arr = np.array(getattr(WIDE, key), float)
            arr[j] *= f
            other = DockingProblem(interval_bounds=WIDE.interval_bounds, **{key: arr})
            T.append(plan(other, weights=(1.0, 0.0), n_front=2, check_sensitivities=False).T)
        fd = (T[0] - T[1]) / (0.02 * row["value"])
        assert row["sensitivity"] == pytest.approx(fd, rel=0.02, abs=1e-3), row
    # the compromise plan: d jerk / d T against re-planning at T ± 1 %
    why = wide_compromise_plan.explanation
    assert why["d_jerk_d_T"] < 0
    assert why["d_jerk_d_T"] == pytest.approx(why["d_jerk_d_T_finite_difference"], rel=0.02)
    for row in why["binding"]:
        assert row["sensitivity"] == pytest.approx(row["finite_difference"], rel=0.05, abs=1e-4), row


def test_a_time_solve_that_cannot_beat_its_start_returns_the_start_with_its_sensitivities(wide_time_plan,
                                                                                        monkeypatch):
    """``solve.min_time`` never answers slower than its certified start: when the SQP finds
    nothing faster (here: nothing at all), the start comes back, with multipliers estimated
    at it, whose sensitivities at the optimum are the SQP's (those checked against
    re-planning above)."""
    s = _summary(wide_time_plan)
    # the plan's x is the least jerk among the shortest; the time programme's own optimum:
    opt = solve.min_time(WIDE, s["x"])
    assert opt.F[0] == pytest.approx(s["T_s"], rel=solve.SHORTEST_SLACK)
    monkeypatch.setattr(solve, "_solve", lambda *args, **kwargs: None)
    sol = solve.min_time(WIDE, opt.x)
    assert sol is not None and not sol.success and sol.iterations == 0
    assert sol.F[0] == pytest.approx(opt.F[0], rel=1e-12) and np.all(sol.G <= 0)
    np.testing.assert_allclose(sol.x, opt.x, rtol=1e-12)
    sens = solve.sensitivities(WIDE, sol)
    names = ["d_L1", "d_L2", "d_L3", "theta_L", "d_R1", "d_R2", "d_R3", "theta_R"]
    rows = s["explanation"]["binding"]
    assert rows
    for row in rows:
        j, k = names.index(row["joint"]), ("travel", "velocity", "acceleration").index(row["quantity"])
        assert sens[j, k] == pytest.approx(row["sensitivity"], rel=0.02, abs=1e-3), row
    # a start that is not a stationary point (the straight line at 3 s per interval, slowed
    # until feasible): kept, but its sensitivities are unknown, not made up
    slow = solve.min_time(WIDE, R.straight_line_x(WIDE.start, WIDE.goal, (3.0,) * 6))
    assert slow is not None and slow.F[0] > s["T_s"] and np.all(slow.G <= 0)
    assert np.isnan(solve.sensitivities(WIDE, slow)).all()


def test_a_plan_of_a_given_duration_is_never_jerkier_than_its_certified_start(wide_time_plan, monkeypatch):
    """A plan of a given duration keeps a certified start when no solve does better (here:
    every least-jerk solve fails): the start comes back slowed to exactly the duration by
    exact time scaling, certified by the dense check and smoother than the start; its
    value of time is unknown, not made up. With no start and no solve there is no answer."""
    s = _summary(wide_time_plan)
    x0 = np.array(s["x"])
    factor = 0.5 * (1.0 + WIDE.interval_bounds[1] / x0[:6].max())  # slower, no interval past its bound
    T = factor * s["T_s"]
    monkeypatch.setattr(solve, "least_jerk", lambda *args, **kwargs: None)
    sol = P._least_jerk_of_duration(WIDE, T, [x0])
    T_ref, J_ref = R.reference_objectives(sol.x, WIDE.start, WIDE.goal, WIDE.arm_distance)
    assert T_ref == pytest.approx(T, rel=1e-12) and J_ref == pytest.approx(sol.F[1], rel=1e-8)
    np.testing.assert_allclose(sol.x[:6], x0[:6] * factor, rtol=1e-12)
    np.testing.assert_array_equal(sol.x[6:], x0[6:])
    _, ok = R.dense_check(WIDE, sol.x[None], n_samples=20001)
    assert ok.all()
    assert J_ref < R.reference_objectives(x0, WIDE.start, WIDE.goal, WIDE.arm_distance)[1]
    why = P.explain(WIDE, sol, P._certify(WIDE, sol.x, 100.0), time_optimal=False, check=False)
    assert why["d_jerk_d_T"] is None and "d jerk / d T = unknown" in P.explain_text(why)
    assert P._least_jerk_of_duration(WIDE, T, []) is None


def test_a_restart_that_does_no_better_does_not_replace_the_answer_before_it(monkeypatch):
    """SLSQP restarted from a solve that stopped short: when the restart ends with a longer
    time and further outside the limits, the answer before it stands (the least jerk at the
    shortest time with knot intervals in [0.05, 30] s, under JAX's default XLA flags, is such
    a case: certified, the restart's point would be slowed from 12.06 s to 19.3 s). SciPy's
    solver is replaced here by one that
    stops at a feasible slow line, then at a point outside every box corner's limits."""
    problem = DockingProblem()
    lo, width = problem.lower, problem.upper - problem.lower
    x_a = solve.straight_line(problem, [40.0])[0]
    u_a = (x_a - lo) / width
    u_b = np.concatenate([np.ones(6), np.zeros(problem.n_var - 6)])  # slower, and every control point at a corner
    assert R.reference_objectives(lo + u_b * width, problem.start, problem.goal, problem.arm_distance)[0] > 40.0
    assert not R.dense_check(problem, (lo + u_b * width)[None], n_samples=2001)[1][0]
    assert R.dense_check(problem, x_a[None], n_samples=2001)[1][0]
    answers = iter([u_a, u_b, u_b, u_b])

    def stopped(fun, u0, **_):
        return OptimizeResult(x=next(answers), success=False, nit=1, message="stopped", fun=fun(u0))

    monkeypatch.setattr(solve, "minimize", stopped)
    x, res, _ = solve._slsqp(problem, x_a, "time", None, 1.0, 1e-12, 10)
    np.testing.assert_allclose(x, x_a, rtol=1e-12)
    assert res.nit == 2


def test_a_limit_that_does_not_bind_has_no_value(wide_time_plan):
    p = _summary(wide_time_plan)
    binding = {r["limit"] for r in p["explanation"]["binding"]}
    assert "d_L1 velocity" not in binding  # 400 mm/s against a few mm/s
    loose = dataclasses.replace(WIDE, velocity=np.asarray(WIDE.velocity) * np.array([2, 1, 1, 1, 1, 1, 1, 1.0]))
    assert plan(loose, weights=(1.0, 0.0), n_front=2, check_sensitivities=False).T == pytest.approx(p["T_s"],
                                                                                                   rel=1e-6)


def test_warm_planner_certifies_new_poses_within_one_percent_of_the_least_jerk_and_chooses_as_plan_does():
    """Each plan passes the dense check, is within 1 % of an independent refinement's
    least jerk at its T, and is the point plan() chooses for the same move (the same
    front ends and Eq. 26 normalisation)."""
    planner = Planner(DockingProblem(), n_front=2)
    planner.plan()
    rng = np.random.default_rng(3)
    half = np.array([5, 5, 5, 0.1, 0.1, 1.0])
    for weights in ((1.0, 1.0), (1.0, 3.0), (1.0, 0.0)):
        s = np.asarray(DockingProblem().start) + rng.uniform(-1, 1, 6) * half
        g = np.asarray(DockingProblem().goal) + rng.uniform(-1, 1, 6) * half
        p = planner.plan(s, g, weights=weights)
        np.testing.assert_allclose(p.problem.start, s)
        _, ok = R.dense_check(p.problem, p.x[None], n_samples=20001)
        assert ok.all()
        ref = refine(p.problem, R.straight_line_x(s, g, (p.T / 6,) * 6)[None], steps=1500)
        assert ref.feasible[0] and ref.F[0, 0] <= p.T * (1 + 1e-12)
        assert p.jerk <= ref.F[0, 1] * 1.01
        q = plan(p.problem, weights=weights, n_front=2, check_sensitivities=False)
        assert p.T == pytest.approx(q.T, rel=1e-6) and p.jerk == pytest.approx(q.jerk, rel=1e-3), weights


def test_min_time_reports_none_when_travel_cannot_be_met():
    x = solve.straight_line(WIDE, [12.0])[0]
    x[6:] = WIDE.upper[6:]  # every interior point at the box corner: far outside d_L2's travel? not always
    out = solve.certify_scaling(dataclasses.replace(WIDE, travel=np.full(8, 1e-3)), x)
    assert out is None
