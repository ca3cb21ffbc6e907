"""Plans of many moves in one compiled call (dockjax.bulk.plan_batch).

References written here, independent of the batched solver: the single-move planner
(:func:`dockjax.plan.plan`, SciPy's SLSQP on the host), the per-joint bang-bang floor and
the dense check of every limit (:mod:`reference`, SciPy's BSpline sampled 20001 times).
One batch of four moves (three feasible, one that no trajectory can make within the interval
bounds) is planned once by weights and once of a given duration: one compiled program, the
shapes of ``bench_plan.py``'s quick form.
"""

from __future__ import annotations

import numpy as np
import pytest

from dockjax.bulk import plan_batch, stack_moves
from dockjax.plan import plan
from dockjax.problem import DockingProblem
from dockjax.solve import PlanError
from tests import reference as R

PROBLEM = DockingProblem(interval_bounds=(0.5, 3.0))
"""Knot intervals in [0.5, 3] s: the longest T (18 s) is below the time some moves need."""
DURATION = 15.0


def _moves():
    rng = np.random.default_rng(7)
    step = np.array([5.0, 5.0, 5.0, 0.1, 0.1, 0.1])
    S = np.asarray(PROBLEM.start) + rng.uniform(-1, 1, (4, 6)) * step
    G = np.asarray(PROBLEM.goal) + rng.uniform(-1, 1, (4, 6)) * step
    G[3, 0] = S[3, 0] - 60.0  # 60 mm of the lateral joint at 2.5 mm/s: at least 24 s
    return S, G


def _floor(start, goal) -> float:
    q0, q1 = R.joints_of_pose(start, PROBLEM.arm_distance), R.joints_of_pose(goal, PROBLEM.arm_distance)
    d = np.abs(q1 - q0)
    v, a = np.asarray(PROBLEM.limits)[:, 1], np.asarray(PROBLEM.limits)[:, 2]
    return float(np.where(d >= v * v / a, d / v + v / a, 2 * np.sqrt(d / a)).max())


@pytest.fixture(scope="module")
def batches(run_once):
    def make(_):
        S, G = _moves()
        return plan_batch(PROBLEM, S, G, n_front=2), plan_batch(PROBLEM, S, G, n_front=2, duration=DURATION)

    return run_once("plan-batch", make)


@pytest.fixture(scope="module")
def singles(run_once):
    """The single-move planner on each move (by weights, and of the duration), or its PlanError.
    It does not wait for :func:`batches`, so two workers compute the two at once."""
    def make(_):
        out = []
        for s, g in zip(*_moves()):
            one = DockingProblem(interval_bounds=PROBLEM.interval_bounds, start=s, goal=g)
            row = []
            for kw in ({}, {"duration": DURATION}):
                try:
                    p = plan(one, n_front=2, check_sensitivities=False, **kw)
                    row.append((p.T, p.jerk, p.settings["shortest_T_s"]))
                except PlanError as e:
                    row.append(e)
            out.append(row)
        return out

    return run_once("plan-batch-singles", make)


def test_the_feasible_moves_are_planned_and_the_impossible_one_is_not(batches):
    by_weights, _ = batches
    S, G = _moves()
    floors = np.array([_floor(s, g) for s, g in zip(S, G)])
    longest = PROBLEM.n_intervals * PROBLEM.interval_bounds[1]
    assert np.array_equal(by_weights.feasible, floors <= longest)
    assert by_weights.feasible[:3].all()
    err = by_weights.errors[3]
    assert isinstance(err, PlanError) and err.joint == "d_L3" and err.quantity == "velocity"
    assert np.isnan(by_weights.x[3]).all() and np.isnan(by_weights.T[3])
    # never faster than the bang-bang floor of its joints
    assert np.all(by_weights.T_min[:3] >= floors[:3] * (1 - 1e-9))


def test_a_batch_and_its_problem_print_in_one_short_line(batches):
    by_weights, _ = batches
    text = repr(by_weights)
    assert text.startswith("BatchPlan(4 moves, 3 feasible, T from ") and len(text) < 120
    assert repr(by_weights.problem) == "DockingProblem(batch of 4 moves, n_var=36)"


def test_every_plan_passes_the_dense_check(batches):
    for result in batches:
        for i in np.flatnonzero(result.feasible):
            one = result.move(i)
            _, ok = R.dense_check(one, result.x[i][None], n_samples=20001)
            assert ok[0], f"move {i}"
            assert result.T[i] == pytest.approx(np.sum(result.x[i][: one.n_intervals]), rel=1e-12)


def test_shortest_times_match_the_single_move_planner(singles, batches):
    by_weights, _ = batches
    for i, (weights_row, _) in enumerate(singles):
        if isinstance(weights_row, PlanError):
            assert not by_weights.feasible[i]  # SLSQP's infeasible moves are never feasible here
            continue
        assert by_weights.T_min[i] == pytest.approx(weights_row[2], rel=1e-3), f"move {i}"


def test_no_chosen_plan_is_dominated_by_the_single_move_planners(singles, batches):
    """The choice is Eq. 26 over a front of three points; where the two fronts differ the
    choices may differ, but the batched plan is never worse in both T and jerk by more than
    0.1 %."""
    by_weights, _ = batches
    for i, (weights_row, _) in enumerate(singles):
        if isinstance(weights_row, PlanError):
            continue
        T, J, _ = weights_row
        assert not (T < by_weights.T[i] * (1 - 1e-3) and J < by_weights.jerk[i] * (1 - 1e-3)), f"move {i}"


def test_plans_of_a_duration_take_it_exactly_and_match_the_single_move_planner(singles, batches):
    _, timed = batches
    assert timed.feasible.any()
    for i, (_, duration_row) in enumerate(singles):
        if isinstance(duration_row, PlanError):
            assert not timed.feasible[i], f"move {i}: SLSQP found no plan of {DURATION} s"
            assert isinstance(timed.errors[i], PlanError)
            continue
        T, J, _ = duration_row
        assert timed.feasible[i]
        assert timed.T[i] == pytest.approx(DURATION, rel=1e-9)
        assert timed.jerk[i] == pytest.approx(J, rel=1e-3), f"move {i}"


def test_a_duration_below_the_shortest_time_names_it(batches):
    by_weights, timed = batches
    short = np.flatnonzero(by_weights.T_min > DURATION)
    assert short.size  # move 0 needs more than 15 s
    for i in short:
        assert not timed.feasible[i] and "shortest feasible time" in str(timed.errors[i])


@pytest.mark.parametrize("starts, goals, match", [
    (np.zeros((2, 5)), np.zeros((2, 6)), "shape"),
    (np.tile(PROBLEM.start, (2, 1)), np.tile(PROBLEM.goal, (3, 1)), "one goal per start"),
    (np.tile(PROBLEM.start, (2, 1)), np.stack([PROBLEM.goal, PROBLEM.start]), "move 1: start and goal are the same"),
    (np.tile(PROBLEM.start, (2, 1)), np.stack([PROBLEM.goal, np.asarray(PROBLEM.goal) + [0, 0, 0, 0, 0, np.nan]]),
     r"goals\[1, 5\] must be finite"),
    (np.tile(PROBLEM.start, (2, 1)), np.stack([PROBLEM.goal, np.asarray(PROBLEM.start) + [0, 0, 0, 0, 0, 40]]),
     "move 1: start-to-goal move of joint theta_L"),
])
def test_bad_moves_are_named_before_any_solve(starts, goals, match):
    with pytest.raises(ValueError, match=match):
        plan_batch(PROBLEM, starts, goals)


def test_bad_options_are_named():
    with pytest.raises(ValueError, match="weights"):
        plan_batch(PROBLEM, weights=(0, 0))
    with pytest.raises(ValueError, match="longest T"):
        plan_batch(PROBLEM, duration=100.0)
    with pytest.raises(ValueError, match="n_front"):
        plan_batch(PROBLEM, n_front=1)


def test_stacked_moves_keep_each_moves_own_box_and_home():
    S, G = _moves()
    P = stack_moves(PROBLEM, S[:2], G[:2])
    for i in range(2):
        one = DockingProblem(start=S[i], goal=G[i], interval_bounds=(0.5, 3.0))
        np.testing.assert_allclose(np.asarray(P.lower)[i], one.lower, rtol=0, atol=0)
        np.testing.assert_allclose(np.asarray(P.upper)[i], one.upper, rtol=0, atol=0)
        np.testing.assert_allclose(np.asarray(P.home)[i], R.default_home(S[i], G[i], one.arm_distance), atol=1e-9)
