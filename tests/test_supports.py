"""A cabin carried by more than two supports (``DockingProblem(supports=...)``).

Every limit column and the jerk objective are checked against ``tests/reference.py``,
whose joints of each support are written there from the pose (SciPy's B-spline and the
support's end ``K_L + o u``; no dockjax code), by dense sampling; the plans by the same
dense check and by where their binding limit lies.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dockjax import cli
from dockjax.bulk import plan_batch
from dockjax.plan import plan
from dockjax.problem import DockingProblem
from dockjax.stages import Via, stage_problems

from . import reference as R

THREE = (0.0, 1000.0, 2000.0)
SLOW_MIDDLE = [400, 25, 2.5, 6.8, 400, 25, 1.2, 6.8, 400, 25, 2.5, 6.8]
"""Velocity limits of a three-support cabin whose middle support's lateral joint is slower."""


def _box_rows(problem, n, seed):
    rng = np.random.default_rng(seed)
    return problem.lower + rng.random((n, problem.n_var)) * (problem.upper - problem.lower)


def test_two_supports_are_the_paper_arms():
    paper, two = DockingProblem(), DockingProblem(supports=(0, 2000))
    assert two.supports is None and two.arm_distance == 2000.0
    assert two.identity() == paper.identity() and "supports" not in paper.identity()
    X = _box_rows(paper, 4, 0)
    for a, b in zip(paper.evaluate(X), two.evaluate(X)):
        np.testing.assert_array_equal(a, b)
    other = DockingProblem(supports=(0, 1500))
    assert other.arm_distance == 1500.0 and other.identity() == DockingProblem(arm_distance=1500).identity()


@pytest.mark.parametrize("supports, mode", [(THREE, "bound"), ((0.0, 800.0, 1900.0, 3000.0), "taylor")])
def test_every_column_of_a_cabin_on_more_supports_is_certified(supports, mode):
    problem = DockingProblem(supports=supports, right_arm=mode,
                             velocity=np.tile([400, 25, 2.5, 6.8], len(supports)) * np.repeat(
                                 np.linspace(1.0, 0.6, len(supports)), 4))
    assert problem.n_joints == 4 * len(supports) and problem.n_con == 12 * len(supports)
    X = _box_rows(problem, 3, 1)
    F, G = problem.evaluate(X, screen=False)
    G_ref, _ = R.dense_check(problem, X)
    # never below the dense maxima (which never exceed the truth), and at most conventions §6's 0.01 above
    assert np.all(G >= G_ref - 1e-12), (G - G_ref).min()
    assert np.all(G - G_ref <= 0.01), (G - G_ref).max()
    for x, f in zip(X, F):
        T, jerk = R.reference_objectives(x, problem.start, problem.goal, supports)
        assert f[0] == pytest.approx(T, rel=1e-12)
        assert f[1] == pytest.approx(jerk, rel=1e-9)


@settings(max_examples=12, deadline=None)
@given(gaps=st.lists(st.floats(50.0, 3000.0), min_size=2, max_size=2), seed=st.integers(0, 2**31 - 1),
       turn=st.floats(-3.0, 3.0))
def test_no_column_of_three_supports_is_understated_anywhere(gaps, seed, turn):
    supports = (0.0, gaps[0], gaps[0] + gaps[1])
    goal = np.array([745, -5, -1515, turn, -turn, 180])
    problem = DockingProblem(supports=supports, goal=goal, right_arm="bound",
                             travel=[600, 200, 200, 15])
    X = _box_rows(problem, 2, seed)
    _, G = problem.evaluate(X)
    G_ref, _ = R.dense_check(problem, X, n_samples=4001)
    assert np.all(G >= G_ref - 1e-12), (G - G_ref).min()


def test_a_three_support_cabin_plans_certified_with_its_own_limits():
    problem = DockingProblem(supports=THREE, velocity=SLOW_MIDDLE)
    p = plan(problem, weights=(1, 0), rate=20)
    assert p.samples["position"].shape[1] == 12
    G, ok = R.dense_check(problem, p.x[None])
    assert ok[0], G.max()
    # the middle support's slower lateral joint decides the time: it rides its limit, and the
    # move takes longer than the shortest the interval bounds allow (6 x 3.5 s, which the
    # paper's two arms reach)
    assert [b["limit"] for b in p.explanation["binding"]] == ["d_M1_3 velocity"]
    assert G.reshape(12, 3)[6, 1] == pytest.approx(0.0, abs=1e-3)
    assert p.T > 21.0 * 1.2


@pytest.mark.parametrize("kw, match", [
    (dict(supports=(5, 1000)), "start at 0"),
    (dict(supports=(0, 2000, 1000)), "increase"),
    (dict(supports=(0,)), "2 to 16"),
    (dict(supports=tuple(range(0, 1700, 100))), "2 to 16"),
    (dict(supports=(0, 1000, float("nan"))), "finite"),
    (dict(supports=THREE, velocity=[1.0] * 8), "velocity must have 4 or 12 numbers"),
    (dict(supports=THREE, home=[0.0] * 8), "home must have 12 numbers"),
    (dict(supports=THREE, arm_distance=1500), "disagree"),
    (dict(supports=THREE, right_arm="adaptive"), "adaptive"),
])
def test_bad_supports_are_refused_by_name(kw, match):
    with pytest.raises(ValueError, match=match):
        DockingProblem(**kw)


def test_the_paths_for_two_arms_refuse_more_supports(tmp_path):
    problem = DockingProblem(supports=THREE)
    with pytest.raises(ValueError, match="two arms; this cabin has 3 supports"):
        plan_batch(problem)
    with pytest.raises(ValueError, match="staged moves are for the paper's two arms; this cabin has 3 supports"):
        stage_problems(problem, [Via(pose=np.array([760, -20, -1420, 0.1, -0.1, 185]))])
    with pytest.raises(ValueError, match="one robot per pair"):
        problem.robot  # noqa: B018
    assert cli.main(["plan", "--supports", "0", "1000", "2000", "--export", "ros2", "--out", str(tmp_path / "o")]) == 2
    assert not (tmp_path / "o").exists()
