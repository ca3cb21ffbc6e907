"""Moves that start or end in motion, and replanning from the state of a running plan.

The end states are checked against SciPy's B-spline derivatives; the limit columns of such
moves against the dense check of ``tests/reference.py``, whose control points next to a
moving end are solved there from SciPy's basis derivatives (no dockjax code); the replan
by the jumps between the two plans where they join.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import BSpline

from dockjax import bspline
from dockjax.plan import Planner, plan
from dockjax.problem import DockingProblem

from . import reference as R

STATES = st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 9), h=st.lists(st.floats(0.05, 20.0), min_size=10, max_size=10), v0=STATES, a0=STATES,
       v1=STATES, a1=STATES, seed=st.integers(0, 2**31 - 1))
def test_the_control_points_of_moving_ends_give_the_end_states(n, h, v0, a0, v1, a1, seed):
    rng = np.random.default_rng(seed)
    h = np.array(h[: n + 1])
    start, goal, interior = rng.normal(size=6) * 100, rng.normal(size=6) * 100, rng.normal(size=(n, 6)) * 100
    with jax.enable_x64(True):
        ctrl = np.asarray(bspline.control_points(start, goal, interior, h, (v0, a0, v1, a1)))
    u = np.concatenate([np.zeros(6), np.cumsum(h)[:-1], np.full(6, h.sum())])
    spline = BSpline(u, ctrl, 5)
    T = h.sum()
    scale = 1.0 + np.abs(ctrl).max() / min(h.min(), 1.0) ** 2
    for t, want in ((0.0, (start, v0, a0)), (T, (goal, v1, a1))):
        for k in range(3):
            np.testing.assert_allclose(spline(t, nu=k), want[k], rtol=0, atol=1e-10 * scale)
    np.testing.assert_array_equal(ctrl[3:-3], interior)


def _moving(seed: int, n_control: int = 5) -> tuple[DockingProblem, np.ndarray]:
    """A paper-like problem whose start and goal are in motion, and candidates in its box."""
    rng = np.random.default_rng(seed)
    base = DockingProblem()
    p = DockingProblem(start_velocity=rng.normal(size=6) * [1, 1, 5, 0.01, 0.01, 0.3],
                       start_acceleration=rng.normal(size=6) * [0.1, 0.1, 0.5, 0.001, 0.001, 0.03],
                       goal_velocity=rng.normal(size=6) * [1, 1, 5, 0.01, 0.01, 0.3],
                       goal_acceleration=rng.normal(size=6) * [0.1, 0.1, 0.5, 0.001, 0.001, 0.03],
                       home=base.home, n_control=n_control, jerk_nodes=base.jerk_nodes)
    X = p.lower + rng.uniform(size=(4, p.n_var)) * (p.upper - p.lower)
    return p, X


@pytest.mark.parametrize("mode", ["bound", "adaptive", "taylor"])
def test_columns_of_moves_in_motion_are_never_below_the_dense_check(mode):
    for seed in range(3):
        p, X = _moving(seed)
        p = p.with_right_arm(mode)
        _, G = p.evaluate(X, screen=False)
        G_dense, _ = R.dense_check(p, X, n_samples=4001)
        assert np.all(np.asarray(G) >= G_dense - 1e-10), (mode, seed, (np.asarray(G) - G_dense).min())


def test_moving_ends_are_none_when_all_zero_and_complete_when_one_is_given():
    assert DockingProblem(start_velocity=np.zeros(6)).boundary is None
    p = DockingProblem(goal_acceleration=[0, 0, 0.1, 0, 0, 0])
    assert [b.tolist() for b in p.boundary] == [[0.0] * 6] * 3 + [[0, 0, 0.1, 0, 0, 0]]
    with pytest.raises(ValueError, match="start_velocity must have 6 numbers"):
        DockingProblem(start_velocity=[1, 2])
    with pytest.raises(ValueError, match="goal_velocity must be finite"):
        DockingProblem(goal_velocity=[np.nan] * 6)


@pytest.fixture(scope="module")
def replanned(run_once):
    """A warm Planner's plan of the paper's move, and its replan at T/3 to the goal moved
    0.3 mm along x, made once: ``(first, second, new goal)``."""
    def make(_):
        planner = Planner(DockingProblem(), rate=100, n_front=3)
        first = planner.plan()
        goal = np.asarray(first.problem.goal) + [0.3, 0, 0, 0, 0, 0]
        return first, planner.replan(first, first.T / 3, goal=goal), goal

    return run_once("replanned", make)


def test_a_replan_at_a_third_joins_continuously_and_is_certified(replanned):
    first, second, goal = replanned
    t = first.T / 3
    assert second.settings["replanned_at_s"] == pytest.approx(t)
    # the independent spline of each plan, the second from the first's state at t
    s1 = R.pose_spline(first.x, first.problem.start, first.problem.goal)
    state = np.stack([s1(t, nu=k) for k in range(3)])
    s2 = R.pose_spline(second.x, state, second.problem.goal)
    for k in range(3):
        scale = np.abs(s1.derivative(k)(np.linspace(0, first.T, 2001)) if k else s1(np.linspace(0, first.T, 2001))
                       ).max()
        jump = np.abs(s2(0.0, nu=k) - s1(t, nu=k)).max()
        assert jump <= 1e-9 * scale, (k, jump, scale)
    np.testing.assert_allclose(s2(second.T), goal, atol=1e-9)
    # certified: the dense check of the second plan's move (from the first's state) passes
    G_dense, ok = R.dense_check(second.problem, second.x[None], n_samples=20001)
    assert ok.all(), G_dense.max()
    # and the plan's own trajectory joins the first's
    for k in range(3):
        np.testing.assert_allclose(second.trajectory.joints([0.0], k), first.trajectory.joints([t], k),
                                   rtol=0, atol=1e-9 * (1 + np.abs(first.samples[("position", "velocity",
                                                                                  "acceleration")[k]]).max()))


def test_a_replan_chooses_the_plan_that_plan_gives_on_its_move(replanned):
    # the replan's front starts from its own shortest slowed to each cap, in fewer SQP
    # iterations; plan() solves the same move from the straight line by continuation
    _, second, _ = replanned
    direct = plan(second.problem, rate=100, n_front=3, check_sensitivities=False)
    assert second.T == pytest.approx(direct.T, rel=1e-3)
    assert second.jerk == pytest.approx(direct.jerk, rel=1e-3)


def test_replan_refuses_a_time_outside_the_plan_and_a_plan_of_another_family(replanned):
    first, _, _ = replanned
    planner = Planner(DockingProblem(), rate=100, n_front=3)
    with pytest.raises(ValueError, match=r"t must be finite and in \[0, "):
        planner.replan(first, first.T + 1.0)
    with pytest.raises(ValueError, match="plan has n_control=5, this planner 3"):
        Planner(DockingProblem(n_control=3)).replan(first, 1.0)


def test_plan_from_a_moving_start_to_its_own_pose_is_a_move():
    base = DockingProblem()
    p = DockingProblem(start=base.goal, goal=base.goal, start_velocity=[0.5, 0, 0, 0, 0, 0], home=base.home)
    out = plan(p, rate=50, n_front=2)
    assert out.T > 0 and np.abs(out.trajectory.pose([0.0], 1)[0] - [0.5, 0, 0, 0, 0, 0]).max() < 1e-9
