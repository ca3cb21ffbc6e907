"""Bad input raises ValueError naming the field and the value; nothing is silently clipped."""

from __future__ import annotations

import numpy as np
import pytest

from dockjax import DockingProblem
from tests import reference as R

START = (775.0, -35.0, -1315.0, 0.2, -0.2, 190.0)
GOAL = (745.0, -5.0, -1515.0, 0.0, 0.0, 180.0)
NAN, INF = float("nan"), float("inf")


def _with(seq, i, v):
    out = list(seq)
    out[i] = v
    return tuple(out)


def _both(field, value):
    """Regex: the message names the field and shows the value (either order)."""
    return rf"(?is)({field}.*{value}|{value}.*{field})"


@pytest.mark.parametrize("field", ["start", "goal"])
@pytest.mark.parametrize(("value", "shown"), [(NAN, "nan"), (INF, "inf"), (-INF, "inf")])
def test_non_finite_pose_raises(field, value, shown):
    pose = _with(START if field == "start" else GOAL, 2, value)
    with pytest.raises(ValueError, match=_both(field, shown)):
        DockingProblem(**{field: pose})


@pytest.mark.parametrize("field", ["travel", "velocity", "acceleration"])
@pytest.mark.parametrize(("value", "shown"), [(NAN, "nan"), (INF, "inf")])
def test_non_finite_limit_raises(field, value, shown):
    default = {"travel": (600, 50, 50, 15), "velocity": (400, 25, 2.5, 6.8),
               "acceleration": (100, 100, 100, 240)}[field]
    with pytest.raises(ValueError, match=_both(field, shown)):
        DockingProblem(**{field: _with(default, 1, value)})


@pytest.mark.parametrize("field", ["travel", "velocity", "acceleration"])
@pytest.mark.parametrize("value", [0.0, -3.0])
def test_non_positive_limit_raises(field, value):
    default = {"travel": (600, 50, 50, 15), "velocity": (400, 25, 2.5, 6.8),
               "acceleration": (100, 100, 100, 240)}[field]
    shown = "0" if value == 0 else "-3"
    with pytest.raises(ValueError, match=_both(field, shown)):
        DockingProblem(**{field: _with(default, 3, value)})


@pytest.mark.parametrize(
    ("field", "value"),
    [("start", START[:5]), ("goal", GOAL + (0.0,)), ("travel", (600, 50, 50)),
     ("velocity", (400, 25, 2.5, 6.8, 1.0)), ("acceleration", (100,))],
)
def test_wrong_length_raises(field, value):
    with pytest.raises(ValueError, match=rf"(?is){field}.*(length|shape|size|entries|\d)"):
        DockingProblem(**{field: value})


@pytest.mark.parametrize(("bounds", "shown"), [((0.0, 10.0), "0"), ((-1.0, 10.0), "-1"),
                                               ((5.0, 5.0), "5"), ((6.0, 4.0), "6"),
                                               ((NAN, 10.0), "nan")])
def test_bad_interval_bounds_raise(bounds, shown):
    with pytest.raises(ValueError, match=_both("interval_bounds", shown)):
        DockingProblem(interval_bounds=bounds)


@pytest.mark.parametrize(("d2", "shown"), [(0.0, "0"), (-2000.0, "-2000"), (NAN, "nan"),
                                           (INF, "inf")])
def test_bad_arm_distance_raises(d2, shown):
    with pytest.raises(ValueError, match=_both("arm_distance", shown)):
        DockingProblem(arm_distance=d2)


def test_move_longer_than_stroke_raises():
    # X moves 150 mm: the lateral joints move 150 mm, beyond their stroke 2 × 50 mm
    start = (775.0, -35.0, -1315.0, 0.0, 0.0, 190.0)
    goal = (925.0, -35.0, -1315.0, 0.0, 0.0, 190.0)
    with pytest.raises(ValueError, match=r"(?is)(travel|stroke).*150|150.*(travel|stroke)"):
        DockingProblem(start=start, goal=goal, travel=(600, 50, 50, 15))
    # a stroke of 2 × 80 mm takes it
    DockingProblem(start=start, goal=goal, travel=(600, 50, 80, 15))


def test_right_arm_move_longer_than_stroke_raises():
    # the left arm does not move in X, but yaw 0 → 3° swings K_R by ~105 mm in X (D2 = 2000)
    start = (775.0, -35.0, -1315.0, 0.0, 0.0, 190.0)
    goal = (775.0, -35.0, -1315.0, 0.0, 3.0, 190.0)
    move = 2000.0 * np.sin(np.deg2rad(3.0))
    assert 100.0 < move < 110.0
    with pytest.raises(ValueError, match=r"(?is)travel|stroke"):
        DockingProblem(start=start, goal=goal, travel=(600, 50, 50, 15))


def test_negative_margin_raises():
    with pytest.raises(ValueError, match=_both("margin", "-0.1")):
        DockingProblem(margin=-0.1)


@pytest.mark.parametrize(("home", "pattern"), [((0.0,) * 7, r"(?is)home"),
                                               ((0.0,) * 7 + (NAN,), _both("home", "nan"))])
def test_bad_home_raises(home, pattern):
    with pytest.raises(ValueError, match=pattern):
        DockingProblem(home=home)


@pytest.fixture(scope="module")
def problem():
    return DockingProblem()


@pytest.mark.parametrize("shape", [(4, 35), (4, 37), (36,), (2, 3, 36)])
def test_X_of_wrong_shape_raises(problem, shape):
    with pytest.raises(ValueError, match=r"(?s)X.*36|36.*X"):
        problem.evaluate(np.ones(shape))


@pytest.mark.parametrize(("value", "shown"), [(NAN, "nan"), (INF, "inf")])
def test_non_finite_X_raises(problem, value, shown):
    rng = np.random.default_rng(0)
    X = rng.uniform(problem.lower, problem.upper, (5, 36))
    X[3, 17] = value
    with pytest.raises(ValueError, match=rf"(?is)\bX\b.*({shown}|finite)"):
        problem.evaluate(X)


@pytest.mark.parametrize(("kw", "match"), [({"precision": "float16"}, "precision"), ({"screen": "no"}, "screen"),
                                           ({"screen": 1}, "screen"), ({"devices": 0}, "devices.*0"),
                                           ({"devices": 2}, "devices.*2"), ({"devices": True}, "devices")])
def test_bad_evaluate_options_raise(problem, kw, match):
    X = np.tile((problem.lower + problem.upper) / 2, (3, 1))
    with pytest.raises(ValueError, match=match):
        problem.evaluate(X, **kw)


@pytest.mark.parametrize("chunk", [0, -3, 2.5, True])
def test_bad_kernel_chunk_raises(problem, chunk):
    from dockjax.problem import score_batch

    X = np.tile((problem.lower + problem.upper) / 2, (3, 1))
    with pytest.raises(ValueError, match=rf"chunk.*{chunk}"):
        score_batch(problem, X, chunk=chunk)


def test_reduced_X_of_full_width_raises():
    p = DockingProblem(reduced=True)
    with pytest.raises(ValueError, match=r"(?s)X.*6"):
        p.evaluate(np.full((2, 36), 5.0))


def test_non_positive_interval_in_X_raises_or_is_not_clipped(problem):
    """An interval ≤ 0 has no trajectory; it must not be clipped to the bound silently."""
    x = R.straight_line_x(START, GOAL, (8.0,) * 6)
    x[2] = -1.0
    try:
        F, G = problem.evaluate(np.tile(x, (16, 1)))
    except ValueError as err:
        assert "X" in str(err) or "interval" in str(err)
    else:  # evaluated as given: T = Σ h with the negative interval, not with 3.5
        assert np.asarray(F)[0, 0] == pytest.approx(np.sum(x[:6]))


def test_X_slightly_outside_box_is_evaluated_as_given(problem):
    rng = np.random.default_rng(3)
    p = problem
    width = p.upper - p.lower
    outside = np.vstack([
        p.upper + 0.05 * width,
        p.lower - 0.05 * width,
        np.where(rng.random(36) < 0.5, p.lower - 0.02 * width, p.upper + 0.02 * width),
    ])
    clipped = np.clip(outside[:1], p.lower, p.upper)
    filler = rng.uniform(p.lower, p.upper, (12, 36))  # 16 rows: the compiled batch of other tests
    F, G = (np.asarray(a) for a in p.evaluate(np.vstack([outside, clipped, filler])))
    assert np.all(np.isfinite(F)) and np.all(np.isfinite(G))
    for i, x in enumerate(outside):
        T, jerk = R.reference_objectives(x, START, GOAL, 2000.0)
        np.testing.assert_allclose(F[i], [T, jerk], rtol=1e-9)
        dense = R.dense_constraints(x, START, GOAL, 2000.0, (600, 50, 50, 15),
                                    (400, 25, 2.5, 6.8), (100, 100, 100, 240), n_samples=10001)
        assert np.all(G[i] >= dense - 1e-9) and np.all(G[i] <= dense + 0.01)
    # clipping would have given the box corner's objectives instead
    assert F[3, 0] != pytest.approx(F[0, 0])
    assert F[3, 1] != pytest.approx(F[0, 1])
