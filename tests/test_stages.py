"""Staged moves (``dockjax plan --move move.toml``): a three-stage docking — approach,
alignment through a via pose passed at speed, insertion at a tenth of the limits after a
stop — planned for the shortest time, checked against the dense check of
``tests/reference.py`` per stage (the control points next to a moving via solved there from
SciPy's basis derivatives), for continuity where the stages meet, and against an
independent solve of the same family (SciPy's SLSQP, finite differences, the reference
spline's sampled limits)."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest
from scipy.optimize import minimize

from dockjax import DockingProblem, cli
from dockjax.stages import check_vias, load_move, stage_problems
from tests import reference as R

MOVE = """\
start = [775, -35, -1315, 0.2, -0.2, 190]
goal = [745, -5, -1515, 0, 0, 180]
[[via]]
pose = [760, -20, -1420, 0.1, -0.1, 185]
stop = false
[[via]]
pose = [750, -10, -1490, 0.02, 0.0, 181]
stop = true
dwell = 1.0
[via.limits]
scale = 0.1
"""
"""The issue's move file, as written."""

BOUNDS = (0.5, 10.0)


def _cli(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(argv)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def staged(run_once):
    """``dockjax plan --move move.toml --interval-bounds 0.5 10 --select time --rate 100``,
    made once: (its summary, what it printed)."""
    def make(folder):
        (folder / "move.toml").write_text(MOVE)
        code, text, err = _cli(["plan", "--move", str(folder / "move.toml"), "--interval-bounds", *map(str, BOUNDS),
                                "--select", "time", "--rate", "100", "--out", str(folder / "plan")])
        assert code == 0, err
        return json.loads((folder / "plan" / "summary.json").read_text()), text, folder / "plan"

    return run_once("staged", make)


def _state(pose, state):
    """A stage end as the reference takes it: a pose (at rest) or a state (3, 6)."""
    return np.asarray(pose, float) if state is None else np.vstack([pose, *state])


def test_the_move_file_of_the_issue_loads_as_written(tmp_path):
    (tmp_path / "m.toml").write_text(MOVE)
    m = load_move(tmp_path / "m.toml")
    assert m["start"].tolist() == [775, -35, -1315, 0.2, -0.2, 190] and len(m["via"]) == 2
    assert not m["via"][0].stop and m["via"][1].stop and m["via"][1].dwell == 1.0
    assert m["via"][1].limits == {"scale": 0.1}
    stages = stage_problems(DockingProblem(start=m["start"], goal=m["goal"]), m["via"])
    base = DockingProblem(start=m["start"], goal=m["goal"])
    np.testing.assert_allclose(stages[2].limits[:, 1:], 0.1 * base.limits[:, 1:])  # the stage leaving via 2
    np.testing.assert_allclose(stages[2].limits[:, 0], base.limits[:, 0])  # travel is geometry
    np.testing.assert_allclose(stages[1].limits, base.limits)
    assert all(np.allclose(s.home, base.home) for s in stages)


@pytest.mark.parametrize("via, message", [
    ([{"stop": False}], "via 1: no pose"),
    ([{"pose": [1, 2, 3]}], "via 1: pose must have 6 numbers"),
    ([{"pose": [760, -20, -1420, 0, 0, 185], "stop": False, "dwell": 2.0}], "via 1: a dwell of 2 s needs stop = true"),
    ([{"pose": [760, -20, -1420, 0, 0, 185], "limits": {"scale": 0}}], r"via 1: limits.scale must be finite and > 0"),
    ([{"pose": [760, -20, -1420, 0, 0, 185], "limits": {"home": [0] * 8}}], "via 1: limits cannot move home"),
    ([{"pose": [760, -20, -1420, 0, 0, 185], "speed": 1}], "via 1: unknown key"),
])
def test_bad_vias_are_refused_naming_the_via(via, message):
    with pytest.raises(ValueError, match=message):
        check_vias(via)


def test_a_bad_move_file_exits_2_with_one_line_before_any_solve(tmp_path):
    bad = tmp_path / "m.toml"
    bad.write_text(MOVE.replace("stop = false", "stop = false\ndwell = 3"))
    code, out, err = _cli(["plan", "--move", str(bad), "--out", str(tmp_path / "p")])
    assert code == 2 and "via 1: a dwell of 3 s needs stop = true" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "p").exists()
    code, _, err = _cli(["plan", "--move", str(bad).replace("m.toml", "none.toml"), "--out", str(tmp_path / "p")])
    assert code == 2 and "move file" in err
    same = tmp_path / "same.toml"
    same.write_text(MOVE.replace("pose = [750, -10, -1490, 0.02, 0.0, 181]", "pose = [745, -5, -1515, 0, 0, 180]"))
    code, _, err = _cli(["plan", "--move", str(same), "--out", str(tmp_path / "p")])
    assert code == 2 and "stage 3: its start and end are the same pose" in err


def test_a_staged_move_is_certified_per_stage_and_continuous_where_it_passes_a_via(staged):
    s, text, folder = staged
    st = s["stages"]
    assert len(st) == 3 and "stage 3" in text
    base = DockingProblem(interval_bounds=BOUNDS)
    splines = []
    for k, stage in enumerate(st):
        x = np.array(stage["x"])
        a, b = _state(stage["start"], stage["start_state"]), _state(stage["goal"], stage["goal_state"])
        lim = np.stack([stage["limits"][q] for q in ("travel", "velocity", "acceleration")], 1)
        g = R.dense_columns(x, a, b, base.arm_distance, lim, home=base.home, n_samples=20001)
        assert g.max() <= 0.0, (k, g.max())
        splines.append(R.pose_spline(x, a, b))
        assert stage["T_s"] == pytest.approx(np.sum(x[:6]), rel=1e-12)
    # the via passed through: the same pose, velocity and acceleration on both sides, not at rest
    T0 = st[0]["T_s"]
    for k in range(3):
        left, right = splines[0](T0, nu=k), splines[1](0.0, nu=k)
        assert np.abs(left - right).max() <= 1e-9 * (1 + np.abs(left).max()), k
    assert np.abs(splines[0](T0, nu=1)).max() > 0.1  # it moves there
    # the stop: at rest, the dwell, then the insertion at a tenth of the limits
    assert np.abs(splines[1](st[1]["T_s"], nu=1)).max() < 1e-9 and st[2]["start_state"] is None
    assert st[2]["start_s"] == pytest.approx(st[1]["start_s"] + st[1]["T_s"] + 1.0)
    assert s["T_s"] == pytest.approx(sum(x["T_s"] for x in st) + 1.0)
    assert any("velocity" in b["limit"] for b in st[2]["binding"])  # the insertion is limited by its slow envelope
    table = np.loadtxt(folder / "trajectory.csv", delimiter=",", skiprows=1)
    assert table[-1, 0] == pytest.approx(s["T_s"]) and np.all(np.diff(table[:, 0]) > 0)


def _sampled(xs, ends, limits, home, arm, per_span=24):
    """``(q / L)² − 1`` of travel, velocity and acceleration at ``per_span`` points of every
    span of every stage (the reference spline)."""
    out = []
    for x, (a, b), lim in zip(xs, ends, limits):
        h = x[:R.n_intervals_of(x)]
        edges = np.concatenate([[0.0], np.cumsum(h)])
        t = np.clip((edges[:-1, None] + np.linspace(0, 1, per_span) * h[:, None]).ravel(), 0, edges[-1])
        qd = R.joint_derivatives(x, a, b, arm, t)
        out += [(((qd[0] - home) / lim[:, 0]) ** 2 - 1).ravel(), ((qd[1] / lim[:, 1]) ** 2 - 1).ravel(),
                ((qd[2] / lim[:, 2]) ** 2 - 1).ravel()]
    return np.concatenate(out)


def _independent_min_time(points, limits, home, arm, through: bool) -> float:
    """The shortest time of a chain of stages through ``points`` (at rest at its ends; at
    the inner point at rest, or passed through with its velocity and acceleration free when
    ``through``), the paper's family: SciPy's SLSQP from straight lines of 30 s per stage,
    finite-difference gradients, sampled limits, restarted from where it stops until it
    reports success (at most four solves). Control points within the start-to-goal
    box of each stage widened by 10 % of its move (1e-3 where it does not move), intervals
    within BOUNDS, via states within ±30 mm/s (°/s) and ±30 mm/s² (°/s²)."""
    lo, hi, n_st = [], [], len(points) - 1
    for k in range(n_st):
        a, b = points[k], points[k + 1]
        m = np.maximum(0.1 * np.abs(b - a), 1e-3)  # a coordinate that does not move: a sliver
        lo += [np.full(6, BOUNDS[0]), np.tile(np.minimum(a, b) - m, 5)]
        hi += [np.full(6, BOUNDS[1]), np.tile(np.maximum(a, b) + m, 5)]
    n_state = 12 * (n_st - 1) if through else 0
    lo, hi = np.concatenate(lo + [np.full(n_state, -30.0)]), np.concatenate(hi + [np.full(n_state, 30.0)])
    w = hi - lo
    rest = np.zeros(6)

    def unpack(u):
        z = lo + u * w
        xs = [z[36 * k:36 * (k + 1)] for k in range(n_st)]
        states = [np.stack([points[0], rest, rest])]
        for k in range(1, n_st):
            off = 36 * n_st + 12 * (k - 1)
            v, acc = (z[off:off + 6], z[off + 6:off + 12]) if through else (rest, rest)
            states.append(np.stack([points[k], v, acc]))
        states.append(np.stack([points[-1], rest, rest]))
        return xs, [(states[k], states[k + 1]) for k in range(n_st)]

    z0 = np.concatenate([np.concatenate([np.full(6, 5.0), (points[k] + np.arange(1, 6)[:, None] / 6
                                                             * (points[k + 1] - points[k])).ravel()])
                         for k in range(n_st)] + [np.zeros(n_state)])
    sel = np.zeros(len(lo))
    for k in range(n_st):
        sel[36 * k:36 * k + 6] = w[36 * k:36 * k + 6]
    u = (z0 - lo) / w
    for _ in range(4):  # SLSQP may stop at a degenerate QP ("constraints incompatible"): go on from its point
        res = minimize(lambda u: sel @ u, u, jac=lambda u: sel, method="SLSQP", bounds=[(0, 1)] * len(lo),
                       constraints=[{"type": "ineq", "fun": lambda u: -_sampled(*unpack(u), limits, home, arm)}],
                       options={"maxiter": 400, "ftol": 1e-10})
        u = res.x
        if res.success:
            break
    assert res.success, res.message
    assert _sampled(*unpack(res.x), limits, home, arm).max() <= 1e-6
    return float(sel @ res.x + sum(lo[36 * k:36 * k + 6].sum() for k in range(n_st)))


def test_the_shortest_staged_time_is_within_0_1_percent_of_an_independent_solve(staged):
    s, _, _ = staged
    st = s["stages"]
    base = DockingProblem(interval_bounds=BOUNDS)
    points = [np.array(x["start"]) for x in st] + [np.array(st[-1]["goal"])]
    limits = [np.stack([x["limits"][q] for q in ("travel", "velocity", "acceleration")], 1) for x in st]
    chain = _independent_min_time(points[:3], limits[:2], base.home, base.arm_distance, through=True)
    insertion = _independent_min_time(points[2:], limits[2:], base.home, base.arm_distance, through=False)
    reference = chain + 1.0 + insertion
    assert s["T_s"] == pytest.approx(reference, rel=1e-3), (s["T_s"], reference)
