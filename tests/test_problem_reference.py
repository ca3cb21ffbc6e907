"""DockingProblem against the independent reference of ``tests/reference.py``.

Objectives must agree to 1e-9 relative; every constraint column must lie in
``[dense − 1e-9, dense + 0.01]`` (conventions §6: never understate, overstate by at most 0.01),
where ``dense`` is the reference's dense check (≥ 1e4 samples plus every knot).
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

from dockjax import DockingProblem
from tests import reference as R

N_DENSE = 10001
BATCH = 35
ROWS = 16
"""Rows per compiled call: the kernel programs the plans and the certified-columns tests compile too."""
"""Rows per evaluate call. One batch size (and few interval bounds) keeps the number of
compilations, which dominate the run time, small."""
F_RTOL = 1e-9
G_BELOW = 1e-9
G_ABOVE = 0.01

DEFAULT = dict(
    start=(775.0, -35.0, -1315.0, 0.2, -0.2, 190.0),
    goal=(745.0, -5.0, -1515.0, 0.0, 0.0, 180.0),
    arm_distance=2000.0,
    interval_bounds=(3.5, 10.0),
    travel=(600.0, 50.0, 50.0, 15.0),
    velocity=(400.0, 25.0, 2.5, 6.8),
    acceleration=(100.0, 100.0, 100.0, 240.0),
)
ARM_JOINTS = ("axial", "lift", "lateral", "roll")
KINDS = ("travel", "velocity", "acceleration")


def _dense(cfg, x, home=None):
    return R.dense_constraints(
        x,
        cfg["start"],
        cfg["goal"],
        cfg["arm_distance"],
        cfg["travel"],
        cfg["velocity"],
        cfg["acceleration"],
        home=home,
        n_samples=N_DENSE,
    )


def _objectives(cfg, x):
    return R.reference_objectives(x, cfg["start"], cfg["goal"], cfg["arm_distance"])


def _check_against_reference(cfg, X, F, G, home=None):
    """Assert F and G of every row of X agree with the reference; return dense G (n, 24)."""
    assert F.shape == (len(X), 2) and G.shape == (len(X), 24)
    assert F.dtype == np.float64 and G.dtype == np.float64
    dense = np.empty_like(G)
    for i, x in enumerate(X):
        T, jerk = _objectives(cfg, x)
        dense[i] = _dense(cfg, x, home)
        np.testing.assert_allclose(F[i], [T, jerk], rtol=F_RTOL, err_msg=f"F of row {i}: {x!r}")
        low = G[i] - (dense[i] - G_BELOW)
        high = (dense[i] + G_ABOVE) - G[i]
        bad = np.flatnonzero((low < 0) | (high < 0))
        assert bad.size == 0, (
            f"row {i}: G columns {bad.tolist()} outside [dense - 1e-9, dense + 0.01]: "
            f"G={G[i, bad].tolist()} dense={dense[i, bad].tolist()} x={x.tolist()}"
        )
    return dense


def _stroke_travel(start, goal, d2, rng, lo=1.05, hi=2.0):
    """Per-arm-joint travel comfortably above half of each joint's start-to-goal move."""
    q = R.joints_of_pose(np.vstack([start, goal]), d2)
    half = 0.5 * np.abs(q[1] - q[0]).reshape(2, 4).max(axis=0)
    return tuple(np.maximum(half * rng.uniform(lo, hi, 4), [5.0, 5.0, 5.0, 1.0]))


def _random_config(rng, attitude=2.0):
    """A random problem: start near the paper's, a move of up to 100/100/300 mm, ±attitude°
    of pitch and yaw and ±10° of roll, D2 in [1500, 3000] mm, limits near the maxima of the
    straight line with the longest intervals (so that some candidates bind)."""
    base = np.array(DEFAULT["start"])
    start = base + np.concatenate(
        [rng.uniform(-50, 50, 3), rng.uniform(-1.5, 1.5, 2), rng.uniform(-10, 10, 1)]
    )
    delta = np.concatenate(
        [rng.uniform(-100, 100, 2), rng.uniform(-300, 300, 1),
         rng.uniform(-attitude, attitude, 2), rng.uniform(-10, 10, 1)]
    )
    goal = start + delta
    d2 = float(rng.uniform(1500.0, 3000.0))
    cfg = dict(
        start=tuple(start),
        goal=tuple(goal),
        arm_distance=d2,
        interval_bounds=((3.5, 10.0), (2.0, 12.0))[int(rng.integers(2))],
        travel=_stroke_travel(start, goal, d2, rng),
    )
    # velocity / acceleration near the straight line's maxima, so that some candidates bind
    x_line = R.straight_line_x(start, goal, (cfg["interval_bounds"][1],) * 6)
    m = R.dense_quantity_maxima(x_line, start, goal, d2, n_samples=2001).reshape(2, 4, 3)
    m = np.maximum(m.max(axis=0), 1e-3)
    cfg["velocity"] = tuple(m[:, 1] * rng.uniform(0.8, 1.6, 4))
    cfg["acceleration"] = tuple(m[:, 2] * rng.uniform(0.8, 1.6, 4))
    return cfg


def _near_feasible(p, cfg, rng, n):
    """Candidates near the straight line with long intervals, inside the box."""
    hi_h = cfg["interval_bounds"][1]
    out = []
    width = p.upper[6:] - p.lower[6:]
    for _ in range(n):
        h = rng.uniform(0.85 * hi_h, hi_h, 6)
        x = R.straight_line_x(cfg["start"], cfg["goal"], h)
        x[6:] += rng.normal(0.0, 0.03, 30) * width
        out.append(np.clip(x, p.lower, p.upper))
    return np.array(out)


CONFIG_SEEDS = [0, 1, 2, 3, 4]


@pytest.mark.parametrize("seed", ["default"] + CONFIG_SEEDS)
def test_evaluate_matches_reference(seed):
    rng = np.random.default_rng(1000 + (0 if seed == "default" else seed + 1))
    cfg = dict(DEFAULT) if seed == "default" else _random_config(rng)
    p = DockingProblem(**cfg)
    X = np.vstack(
        [rng.uniform(p.lower, p.upper, (25, p.n_var)), _near_feasible(p, cfg, rng, BATCH - 25)]
    )
    F, G = p.evaluate(X, rows=ROWS)
    F, G = np.asarray(F), np.asarray(G)
    _check_against_reference(cfg, X, F, G)


def _paper_like_config(seed):
    """The paper's problem, moved a little: poses within ±20 mm, ±0.2° of pitch and yaw."""
    rng = np.random.default_rng(3000 + seed)

    def d():
        return np.r_[rng.uniform(-20, 20, 3), rng.uniform(-0.2, 0.2, 2), rng.uniform(-2, 2, 1)]

    return dict(
        DEFAULT,
        start=tuple(np.array(DEFAULT["start"]) + d()),
        goal=tuple(np.array(DEFAULT["goal"]) + d()),
        arm_distance=float(rng.uniform(1500, 2500)),
        travel=(600.0, 60.0, 60.0, 15.0),
    )


@pytest.mark.parametrize(
    ("seed", "right_arm"),
    [("paper", "bound"), ("paper", "taylor"), (0, "bound"), (2, "bound"), (1, "auto"),
     (4, "auto"), (1, "adaptive")],
)
def test_right_arm_modes_match_reference(seed, right_arm):
    """Every way of finding the right arm's nonlinear maxima meets conventions §6 where it claims
    to: "bound" on paper-sized attitude changes (tenths of a degree), "taylor" anywhere."""
    rng = np.random.default_rng(2000 + (0 if seed == "paper" else seed + 1))
    cfg = dict(DEFAULT) if seed == "paper" else _paper_like_config(seed)
    p = DockingProblem(**cfg, right_arm=right_arm)
    X = np.vstack(
        [rng.uniform(p.lower, p.upper, (20, p.n_var)), _near_feasible(p, cfg, rng, BATCH - 20)]
    )
    F, G = (np.asarray(a) for a in p.evaluate(X, rows=ROWS))
    _check_against_reference(cfg, X, F, G)


def test_evaluate_covers_at_least_200_candidates():
    """The parametrised comparison above sees at least 200 candidates."""
    assert (1 + len(CONFIG_SEEDS) + 6 + 6) * BATCH >= 200


def test_evaluate_without_caller_x64_returns_float64_and_leaves_flag():
    before = bool(jax.config.jax_enable_x64)
    p = DockingProblem()
    x = R.straight_line_x(DEFAULT["start"], DEFAULT["goal"], (9.0, 7.0, 8.0, 6.0, 9.5, 8.5))
    F, G = p.evaluate(np.tile(x, (BATCH, 1)), rows=ROWS)
    assert isinstance(F, np.ndarray) and isinstance(G, np.ndarray)
    assert F.dtype == np.float64 and G.dtype == np.float64
    assert bool(jax.config.jax_enable_x64) == before
    # float32 would lose this: jerk of a long smooth move is ~0.2 and needs 1e-9 relative
    T, jerk = _objectives(DEFAULT, x)
    np.testing.assert_allclose(F[0], [T, jerk], rtol=F_RTOL)


def test_jerk_nodes_follow_the_attitude_range_and_reach_1e9():
    """conventions §5: the right arm's jerk integral to 1e-9 relative. The Gauss–Legendre nodes per
    span come from the box's range of pitch and yaw: 8 for the paper's box; 12 for a box of
    2.6° (tests/test_properties.py), where hypothesis found a candidate — a 0.5 s span
    sweeping the whole pitch range — on which 8 nodes miss 1e-9; 24 beyond 8°. No kernel
    is compiled here."""
    assert DockingProblem().jerk_nodes == 8
    start, goal = (700.0, 20.0, -1300.0, -1.0, 1.5, 175.0), (760.0, -10.0, -1450.0, 1.2, -1.0, 183.0)
    kw = dict(start=start, goal=goal, arm_distance=2800.0, interval_bounds=(0.1, 100.0),
              travel=(600.0, 150.0, 150.0, 15.0))
    p = DockingProblem(**kw)
    assert p.jerk_nodes == 12 and p.with_right_arm("taylor").jerk_nodes == 12
    lo, hi = p.lower[6:], p.upper[6:]
    fractions = np.zeros(30)
    fractions[2:4] = (0.75, 1.0)
    x = np.concatenate([[2.0, 1.0, 0.5, 9.0, 1.0, 2.0], lo + fractions * (hi - lo)])
    _, jerk = R.reference_objectives(x, start, goal, 2800.0, nodes=40)
    # 8 nodes are not enough here, 12 are (the reference's own quadrature shows it; the
    # kernel meets 1e-9 on this candidate in tests/test_properties.py's pinned example)
    err = lambda nodes: abs(R.reference_objectives(x, start, goal, 2800.0, nodes=nodes)[1] - jerk) / jerk  # noqa: E731
    assert err(8) > 1e-9 and err(12) <= 1e-12
    turn = DockingProblem(start=(775.0, -35.0, -1315.0, 10.0, -10.0, 190.0), goal=DEFAULT["goal"],
                          travel=(3000.0, 3000.0, 3000.0, 15.0))
    assert turn.jerk_nodes == 24
    for bad in (2, 65, 2.5, True):
        with pytest.raises(ValueError, match="jerk_nodes"):
            DockingProblem(jerk_nodes=bad)


def test_defaults_are_the_paper_and_spec_values():
    p = DockingProblem()
    assert (p.n_var, p.n_obj, p.n_con) == (36, 2, 24)
    lo, hi = R.reference_bounds(DEFAULT["start"], DEFAULT["goal"], (3.5, 10.0), 0.1)
    np.testing.assert_allclose(p.lower, lo, rtol=1e-15, atol=1e-12)
    np.testing.assert_allclose(p.upper, hi, rtol=1e-15, atol=1e-12)
    assert p.lower.dtype == np.float64 and p.upper.dtype == np.float64
    want = R.expand_limits(DEFAULT["travel"], DEFAULT["velocity"], DEFAULT["acceleration"])
    np.testing.assert_array_equal(np.asarray(p.limits), want)
    home = R.default_home(DEFAULT["start"], DEFAULT["goal"], 2000.0)
    np.testing.assert_allclose(np.asarray(p.home), home, rtol=1e-12, atol=1e-9)


def test_bounds_use_zero_move_margins_and_margin():
    start = (700.0, -20.0, -1300.0, 0.5, 0.0, 180.0)
    goal = (700.0, 10.0, -1400.0, 0.5, 1.0, 180.0)  # x, pitch and roll do not move
    p = DockingProblem(start=start, goal=goal, interval_bounds=(2.0, 12.0), margin=0.25,
                       travel=(600, 100, 100, 15))
    lo, hi = R.reference_bounds(start, goal, (2.0, 12.0), 0.25)
    np.testing.assert_allclose(p.lower, lo, atol=1e-12)
    np.testing.assert_allclose(p.upper, hi, atol=1e-12)
    # spelled out: x ± 1 mm, pitch/roll ± 0.01°, z widened by 0.25·100
    assert p.lower[6] == pytest.approx(699.0) and p.upper[6] == pytest.approx(701.0)
    assert p.lower[9] == pytest.approx(0.49) and p.upper[9] == pytest.approx(0.51)
    assert p.lower[8] == pytest.approx(-1425.0) and p.upper[8] == pytest.approx(-1275.0)


def test_custom_home_moves_travel_columns():
    rng = np.random.default_rng(7)
    cfg = dict(DEFAULT)
    home = R.default_home(cfg["start"], cfg["goal"], 2000.0) + rng.uniform(-5, 5, 8)
    p = DockingProblem(**cfg, home=tuple(home))
    np.testing.assert_allclose(np.asarray(p.home), home, atol=1e-12)
    X = np.vstack(
        [_near_feasible(p, cfg, rng, 10), rng.uniform(p.lower, p.upper, (BATCH - 10, 36))]
    )
    F, G = p.evaluate(X, rows=ROWS)
    _check_against_reference(cfg, X, np.asarray(F), np.asarray(G), home=home)


# --- each kind of limit binds, for each arm -------------------------------------------

BIND_H = (4.0, 9.0, 6.0, 5.0, 8.0, 7.0)
LATERAL = 2  # arm-joint index of the lateral joint (task X)


def _binding_config(kind, arm):
    """A problem whose straight-line candidate is held by one (kind, arm) lateral column.

    Left case: X moves +80 mm while yaw turns −1.2° (D2 = 2500), so K_R moves only
    ~28 mm in X. Right case: X moves 10 mm while yaw turns +2°, so K_R moves ~97 mm.
    Limits: loose (10 × the maxima) everywhere except the target, set 0.1 % above it.
    """
    k = KINDS.index(kind)
    start = np.array([775.0, -35.0, -1315.0, 0.0, 0.0, 190.0])
    if arm == "left":
        goal = start + [80.0, 5.0, -150.0, 0.3, -1.2, -4.0]
    else:
        goal = start + [10.0, 5.0, -150.0, 0.3, 2.0, -4.0]
    d2 = 2500.0
    x0 = R.straight_line_x(start, goal, BIND_H)
    m = R.dense_quantity_maxima(x0, start, goal, d2, n_samples=N_DENSE)  # (8, 3)
    lim = 10.0 * np.maximum(m.reshape(2, 4, 3).max(axis=0), 1e-2)  # (4, 3)
    joint = LATERAL + (0 if arm == "left" else 4)
    lim[LATERAL, k] = m[joint, k] / (1.0 - 1e-3)
    cfg = dict(
        start=tuple(start), goal=tuple(goal), arm_distance=d2, interval_bounds=(3.5, 10.0),
        travel=tuple(lim[:, 0]), velocity=tuple(lim[:, 1]), acceleration=tuple(lim[:, 2]),
    )
    return cfg, x0, 3 * joint + k


@pytest.mark.parametrize("arm", ["left", "right"])
@pytest.mark.parametrize("kind", KINDS)
def test_each_limit_kind_binds_for_each_arm(kind, arm):
    cfg, x0, col = _binding_config(kind, arm)
    rng = np.random.default_rng(100 * KINDS.index(kind) + (arm == "right"))
    p = DockingProblem(**cfg)
    X = [x0]
    width = p.upper - p.lower
    for _ in range(BATCH - 1):
        x = x0 + rng.normal(0.0, 0.01, 36) * width
        x[:6] = np.clip(x[:6], 3.5, 10.0)
        X.append(x)
    X = np.array(X)
    F, G = p.evaluate(X, rows=ROWS)
    F, G = np.asarray(F), np.asarray(G)
    dense = _check_against_reference(cfg, X, F, G)
    # the set-up: the reference says this column holds x0, just inside its limit
    assert int(np.argmax(dense[0])) == col
    assert -2e-3 < dense[0, col] <= 0.0
    # the kernel agrees that it is the binding column
    assert int(np.argmax(G[0])) == col, (G[0].reshape(8, 3), col)
    assert -2e-3 < G[0, col] < G_ABOVE
    other = col + (12 if arm == "left" else -12)  # same joint and kind, other arm
    assert G[0, other] < G[0, col] - 0.1


# --- the reduced setting ---------------------------------------------------------------


def test_reduced_equals_full_with_points_on_the_line():
    rng = np.random.default_rng(11)
    cfg = _random_config(rng)
    pr = DockingProblem(**cfg, reduced=True)
    pf = DockingProblem(**cfg)
    assert (pr.n_var, pr.n_obj, pr.n_con) == (6, 2, 24)
    lo, hi = cfg["interval_bounds"]
    np.testing.assert_array_equal(pr.lower, np.full(6, lo))
    np.testing.assert_array_equal(pr.upper, np.full(6, hi))
    H = rng.uniform(pr.lower, pr.upper, (BATCH, 6))
    Xf = np.array([R.reduced_to_full(h, cfg["start"], cfg["goal"]) for h in H])
    Fr, Gr = (np.asarray(a) for a in pr.evaluate(H, rows=ROWS))
    Ff, Gf = (np.asarray(a) for a in pf.evaluate(Xf, rows=ROWS))
    np.testing.assert_allclose(Fr, Ff, rtol=1e-11)
    np.testing.assert_allclose(Gr, Gf, rtol=1e-11, atol=1e-11)
    _check_against_reference(cfg, Xf, Fr, Gr)
    traj = pr.decode(H[0])
    np.testing.assert_allclose(
        np.asarray(traj.control_points), R.control_points(Xf[0], cfg["start"], cfg["goal"]),
        rtol=1e-13, atol=1e-10,
    )


# --- decode ----------------------------------------------------------------------------


def test_decode_matches_reference():
    rng = np.random.default_rng(21)
    cfg = _random_config(rng)
    p = DockingProblem(**cfg)
    for x in rng.uniform(p.lower, p.upper, (3, 36)):
        traj = p.decode(x)
        assert traj.T == pytest.approx(np.sum(x[:6]), rel=1e-14)
        np.testing.assert_allclose(np.asarray(traj.intervals), x[:6], rtol=1e-15)
        np.testing.assert_allclose(np.asarray(traj.knots), R.knots(x[:6]), rtol=1e-14)
        np.testing.assert_allclose(
            np.asarray(traj.control_points), R.control_points(x, cfg["start"], cfg["goal"]),
            rtol=1e-15,
        )
        t = np.concatenate([[0.0, traj.T], R.knots(x[:6])[6:11], rng.uniform(0, traj.T, 40)])
        pd = R.pose_derivatives(x, cfg["start"], cfg["goal"], t)
        qd = R.joint_derivatives(x, cfg["start"], cfg["goal"], cfg["arm_distance"], t)
        for k in range(4):
            pose = np.asarray(traj.pose(t, derivative=k))
            q = np.asarray(traj.joints(t, derivative=k))
            assert pose.shape == (len(t), 6) and q.shape == (len(t), 8)
            scale_p = max(1.0, np.abs(pd[k]).max())
            scale_q = max(1.0, np.abs(qd[k]).max())
            np.testing.assert_allclose(pose, pd[k], rtol=1e-9, atol=1e-9 * scale_p)
            np.testing.assert_allclose(q, qd[k], rtol=1e-9, atol=1e-9 * scale_q)
        # boundary conditions of conventions §2
        np.testing.assert_allclose(np.asarray(traj.pose([0.0]))[0], cfg["start"], atol=1e-9)
        np.testing.assert_allclose(np.asarray(traj.pose([traj.T]))[0], cfg["goal"], atol=1e-9)
        for k in (1, 2):
            np.testing.assert_allclose(np.asarray(traj.pose([0.0, traj.T], derivative=k)), 0.0,
                                       atol=1e-9)


def test_to_csv_rows_at_rate_and_final_row_at_T(tmp_path):
    cfg = dict(DEFAULT)
    p = DockingProblem(**cfg)
    h = (7.13, 8.2, 6.05, 9.9, 7.77, 8.31)  # T = 47.36 s, not a multiple of 1/rate
    x = R.straight_line_x(cfg["start"], cfg["goal"], h)
    x[6:] += np.random.default_rng(3).normal(0, 0.02, 30) * (p.upper - p.lower)[6:]
    traj = p.decode(x)
    rate = 4.0
    path = tmp_path / "traj.csv"
    traj.to_csv(path, rate)
    with open(path) as fh:
        header = fh.readline().strip()
    names = [c.strip() for c in header.split(",")]
    assert not any(_is_number(c) for c in names), header
    assert "mm" in header and "deg" in header and "s" in header
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    assert data.shape[1] == len(names)
    T = float(np.sum(h))
    k = np.arange(int(np.floor(T * rate + 1e-9)) + 1)
    want_t = np.concatenate([k / rate, [T]])
    np.testing.assert_allclose(data[:, 0], want_t, rtol=0, atol=1e-9)
    assert data[-1, 0] == pytest.approx(T, abs=1e-12 * T)
    # every pose coordinate and every joint appears as a column matching the reference,
    # and every column is the pose or a joint or one of the joints' derivatives 1..3
    pose = R.pose_derivatives(x, cfg["start"], cfg["goal"], want_t, 0)[0]
    qd = R.joint_derivatives(x, cfg["start"], cfg["goal"], cfg["arm_distance"], want_t)

    def same(col, ref):
        return np.allclose(col, ref, rtol=1e-7, atol=1e-7 * max(1.0, np.abs(ref).max()))

    for ref in np.hstack([pose, qd[0]]).T:
        assert any(same(col, ref) for col in data[:, 1:].T), "a pose or joint column is missing"
    refs = np.hstack([pose, *qd]).T
    for name, col in zip(names[1:], data[:, 1:].T):
        assert any(same(col, ref) for ref in refs), f"CSV column {name} matches no reference"


def _is_number(s):
    try:
        float(s)
    except ValueError:
        return False
    return True


# --- the reference itself --------------------------------------------------------------


def test_reference_chain_rule_matches_finite_differences():
    """Sanity of the reference: its right-arm derivatives against a 5-point stencil."""
    rng = np.random.default_rng(5)
    cfg = _random_config(rng)
    lo, hi = R.reference_bounds(cfg["start"], cfg["goal"], cfg["interval_bounds"])
    x = rng.uniform(lo, hi)
    T = x[:6].sum()
    # points inside spans (the spline is only C^4 at knots)
    kn = R.knots(x[:6])[5:12]
    t = 0.5 * (kn[:-1] + kn[1:])
    qd = R.joint_derivatives(x, cfg["start"], cfg["goal"], cfg["arm_distance"], t)
    e = 1e-3 * T

    def d(k):
        f = lambda tt: qd_at(tt, k - 1)  # noqa: E731
        return (f(t - 2 * e) - 8 * f(t - e) + 8 * f(t + e) - f(t + 2 * e)) / (12 * e)

    def qd_at(tt, k):
        return R.joint_derivatives(x, cfg["start"], cfg["goal"], cfg["arm_distance"], tt)[k]

    for k in (1, 2, 3):
        scale = max(1.0, np.abs(qd[k]).max())
        np.testing.assert_allclose(d(k), qd[k], atol=1e-6 * scale)


def test_reference_straight_line_default_is_feasible():
    x = R.straight_line_x(DEFAULT["start"], DEFAULT["goal"], (10.0,) * 6)
    c = DEFAULT
    assert R.dense_feasible(x, c["start"], c["goal"], 2000.0, c["travel"], c["velocity"],
                            c["acceleration"])
    T, jerk = R.reference_objectives(x, c["start"], c["goal"], 2000.0)
    assert T == 60.0 and 0.0 < jerk < 1.0
    # and a fast one is not (lateral speed 2.5 mm/s is the tight limit: T = 12 s)
    x = R.straight_line_x(c["start"], c["goal"], (2.0,) * 6)
    assert not R.dense_feasible(x, c["start"], c["goal"], 2000.0, c["travel"], c["velocity"],
                                c["acceleration"])


# --- regression cases: extrema that are easy to miss ------------------------------------

# Roll travel (columns 9 and 21): on span 0 the roll's derivative has a double root at the
# clamped start and another root at τ ≈ 0.1213 s inside a long monotone bracket; the true
# max of |θ − home| is there, a hair above its start value.
HARD_ROLL_CFG = dict(
    start=(
        743.7757368268633, -59.329418978117786, -1315.532067281115, 0.6823746724525559,
        0.5563385850282307, 194.46195736279353,
    ),
    goal=(
        711.8631767276793, -39.82130127848656, -1033.1857997738714, 1.5091912343193916,
        -0.5755224731090796, 187.2759635506955,
    ),
    arm_distance=2560.7962434408955,
    interval_bounds=(3.5, 10.0),
    travel=(200.47282848319546, 32.71633679391716, 64.2919610140878, 5.574963042263732),
    velocity=(9.25638515035688, 1.1221705107707054, 2.9119464858027038, 0.22033405717489118),
    acceleration=(
        0.7653906809918681, 0.2592033855248108, 0.30452545830032285, 0.030816963974923044,
    ),
)
HARD_ROLL_X = [
    5.505240443054811, 5.499745178576162, 7.280892814215193,
    8.962111090394194, 5.240474860051589, 7.8056937968951985,
    726.4894786962311, -43.31493491032994, -1306.7607281303103,
    1.4311861146077343, -0.5021973702574585, 194.47421698872495,
    717.1443159233157, -49.47781543329395, -1037.094420047322,
    0.9371986424864462, -0.15043215010652344, 190.40527427746673,
    739.5088496295537, -53.386630857674675, -1254.4645193413553,
    1.540037042984642, 0.2204558227472243, 192.64881012695255,
    728.4601259091836, -58.00317037329569, -1067.7646583509727,
    1.0776409516706524, -0.3408956030290938, 187.14039281850523,
    739.0809856811884, -40.49185263032764, -1171.6238317969041,
    0.6535933318223026, -0.13194149476331107, 191.9809358261159,
    ]

# Right axial acceleration (column 14 = d_R1, acceleration): max |d_R1''| at t ≈ 50.65 s, in
# the last span, through the nonlinear cos α cos β term.
HARD_RIGHT_CFG = dict(
    start=(
        820.6001709628976, -64.23181899208531, -1282.155511472547, -0.8521536307539392,
        -0.16158615069030563, 182.71839208041013,
    ),
    goal=(
        858.4074669191237, 4.117725870370478, -1326.850113029561, 0.9755503830595256,
        1.1397454748488876, 179.48269832984164,
    ),
    arm_distance=2363.6408219167706,
    interval_bounds=(2.0, 12.0),
    travel=(43.8038100980706, 85.36629061742283, 80.4254682005963, 1.912915975327238),
    velocity=(1.4917710647173683, 2.9671921014409945, 2.8544705987902255, 0.07116048465122744),
    acceleration=(
        0.20380200884019964, 0.4813111266892912, 0.2669039104094595, 0.009154227813648672,
    ),
)
HARD_RIGHT_X = [
    10.626434446391695, 10.2333993407788, 8.316792232203909,
    8.026031187835342, 6.862217156911929, 10.639110146920956,
    822.2604737616009, -28.566507453773035, -1294.0192027385367,
    -0.8122170985742805, -0.02705238293983575, 181.36484443253917,
    819.2785700523887, -48.957084401035374, -1289.3478844398894,
    -1.0115114638360112, 0.3491924939000203, 181.87236495308883,
    828.3474525812416, -31.927784416366755, -1292.8093208101275,
    0.8810357136863667, 0.3573263160839668, 181.6489616654335,
    856.3550047376626, -26.95334287177262, -1295.4778036840842,
    0.2749607726732197, 0.5981394520921288, 183.01204965080495,
    844.9506815433564, -37.99703358260354, -1315.4491554720769,
    -1.0311447849938002, 0.09861264931112623, 181.18907681934044,
    ]


@pytest.mark.parametrize(
    ("cfg", "x", "col"),
    [(HARD_ROLL_CFG, HARD_ROLL_X, 9), (HARD_RIGHT_CFG, HARD_RIGHT_X, 14)],
    ids=["roll_travel_near_clamped_start", "right_axial_acceleration"],
)
def test_hard_extrema_are_not_understated(cfg, x, col):
    x = np.asarray(x)
    p = DockingProblem(**cfg)
    F, G = (np.asarray(a) for a in p.evaluate(np.tile(x, (BATCH, 1)), rows=ROWS))
    dense = _check_against_reference(cfg, x[None, :], F[:1], G[:1])
    assert G[0, col] >= dense[0, col] - G_BELOW


def test_dense_check_reads_a_problem():
    """The population-level dense check (used later to certify optimiser results)."""
    p = DockingProblem()
    x = R.straight_line_x(DEFAULT["start"], DEFAULT["goal"], (10.0,) * 6)
    G, ok = R.dense_check(p, np.vstack([x, R.straight_line_x(DEFAULT["start"], DEFAULT["goal"],
                                                             (2.0,) * 6)]), n_samples=2001)
    assert G.shape == (2, 24) and ok.tolist() == [True, False]
    want = R.dense_constraints(x, DEFAULT["start"], DEFAULT["goal"], 2000.0, DEFAULT["travel"],
                               DEFAULT["velocity"], DEFAULT["acceleration"], n_samples=2001)
    np.testing.assert_allclose(G[0], want, rtol=1e-14)
    Gr, okr = R.dense_check(DockingProblem(reduced=True), np.full((1, 6), 10.0), n_samples=2001)
    np.testing.assert_allclose(Gr[0], want, rtol=1e-14)


# Right axial velocity (column 13): max |d_R1'| at t ≈ 27.153 s inside span 3, a candidate
# with short intervals and interior points far from the line (found by a stress sweep).
HARD_RIGHT_VEL_CFG = dict(
    start=(
        748.5798804812533, -42.08930013341889, -1355.7726983446707, 0.47780827086413097,
        0.6480960400140658, 197.35155994162264,
    ),
    goal=(
        713.8708517217701, -120.17322579149416, -1416.4870090564891, 0.8442190466373425,
        -0.3512119349954752, 200.23377547726508,
    ),
    arm_distance=2853.477478517625,
    interval_bounds=(2.0, 12.0),
    travel=(45.75100147512098, 69.45213919000321, 68.8666447318853, 2.5313735452506423),
    velocity=(1.375372436550465, 2.1952097687040415, 1.4575683034066502, 0.06874627295135416),
    acceleration=(
        0.11629307301399766, 0.26626288413697097, 0.21023620972355742, 0.005608257098442839,
    ),
)
HARD_RIGHT_VEL_X = [
    9.751134920434176, 3.1029231679675604, 12.440739398052179,
    2.569871729015987, 2.009516738815841, 5.176531965223682,
    697.0368380293046, 47.23185626808038, -1430.607241679247,
    0.15701545928063357, 1.5237716148438762, 202.32461968547557,
    754.2276782494282, -116.27981398860814, -1284.5393853475357,
    0.9225434214132868, 0.7639528424044197, 194.56659496493694,
    720.2636765946049, 57.68840459110521, -1265.2413704994672,
    1.1870267832527335, 1.0478916744630844, 203.47427303892783,
    698.5581489699347, -88.26623416717624, -1342.0986813788354,
    0.3023640999267019, 1.301532867593568, 193.605386332176,
    793.2960466442192, -222.57038375768911, -1391.1089776496892,
    -0.014427793586202893, -1.648254439268022, 195.0166504523688,
]


def test_hard_right_velocity_is_not_understated():
    x = np.asarray(HARD_RIGHT_VEL_X)
    cfg = HARD_RIGHT_VEL_CFG
    p = DockingProblem(**cfg)
    F, G = (np.asarray(a) for a in p.evaluate(np.tile(x, (BATCH, 1)), rows=ROWS))
    dense = _check_against_reference(cfg, x[None, :], F[:1], G[:1])
    assert G[0, 13] >= dense[0, 13] - G_BELOW
