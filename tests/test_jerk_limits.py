"""Jerk limits (``DockingProblem(jerk=...)``): four limit kinds per joint, every column certified.

With jerk limits G has 32 columns, joint-major (``"d_L1 travel"``, ``"d_L1 velocity"``,
``"d_L1 acceleration"``, ``"d_L1 jerk"``, ``"d_L2 travel"``, ...). Every column must be at
or above the true ``max_t |q_j^(k)| / limit − 1`` in every right-arm mode, screened or not;
the jerk of the joints linear in the pose (a quadratic per knot span) is exact to rounding.
The truth is bracketed from below by the dense sampling of ``tests/reference.py`` (SciPy
``BSpline`` and an explicit chain rule: no dockjax code), so the only slack allowed below it
is rounding (:data:`REL` of the value). Without jerk limits nothing changes: 24 columns,
bit for bit the first three kinds of the problem with jerk limits (checked in the bound
mode; in ``"taylor"`` and ``"adaptive"`` the right arm's sub-spans are chosen for every kind
at once, so its columns may come out tighter with jerk limits than without).
"""

from __future__ import annotations

import contextlib
import io
import json
import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from dockjax import DockingProblem, cli
from dockjax.plan import load_limits, plan
from tests import reference as R

MODES = ("auto", "bound", "taylor", "adaptive")
JOINT_NAMES = ("d_L1", "d_L2", "d_L3", "theta_L", "d_R1", "d_R2", "d_R3", "theta_R")
KINDS = ("travel", "velocity", "acceleration", "jerk")
LINEAR = np.array([0, 1, 2, 3, 7])
"""The joints linear in the pose (exact columns); the others (4, 5, 6) go through sin/cos."""
JERK_NODES = 8
"""One node count for every drawn configuration (one compiled kernel per mode and family;
the nodes change F only)."""
N_DENSE = 20001
N_PROPERTY = 10001
"""Samples of the property tests' dense check (then refined around the largest sample)."""
BELOW = 1e-10
"""Absolute slack (units of the limit) below the dense lower bound: the reference's rounding."""
REL = 1e-9
"""Relative slack below the dense lower bound: rounding of values far from the limit."""
EXACT = 1e-6
"""Relative agreement of an exact column (linear joints' jerk) with the refined dense maximum."""
EXAMPLES = 15 if settings.default.max_examples <= 25 else settings.default.max_examples


def kind_names(p) -> tuple:
    return tuple(getattr(k, "name", k) for k in p.kinds)


def scaled(x, s):
    """x with its knot intervals times s: velocity ∝ 1/s, acceleration ∝ 1/s², jerk ∝ 1/s³."""
    y = np.array(x, dtype=np.float64)
    y[:R.n_intervals_of(y)] *= s
    return y


def dense(p, X, n_samples: int = N_DENSE) -> np.ndarray:
    """Dense-sampled G (n, 8 K) of the rows of X from the problem's data only."""
    lim = np.asarray(p.limits, dtype=np.float64)
    return np.array([R.dense_columns(x, p.start, p.goal, p.arm_distance, lim, home=p.home, n_samples=n_samples)
                     for x in np.atleast_2d(X)])


def assert_certified(G, lower, what: str, X):
    """Every column of G at or above the dense lower bound, but for rounding."""
    assert G.shape == lower.shape, (G.shape, lower.shape)
    short = (G - lower) / (BELOW + REL * np.abs(lower + 1.0))  # ≥ −1 allowed
    i, c = np.unravel_index(np.argmin(short), short.shape)
    names = [f"{j} {k}" for j in JOINT_NAMES for k in KINDS[: G.shape[1] // 8]]
    assert short[i, c] >= -1.0, (
        f"{what}: column {c} ({names[c]}) of row {i} understated: G={G[i, c]!r} < dense {lower[i, c]!r} "
        f"(by {lower[i, c] - G[i, c]:.3g} of the limit); x={X[i].tolist()}")


def assert_linear_jerk_exact(G, lower, what: str):
    """The jerk columns of the linear joints equal the (refined) dense maximum."""
    cols = 4 * LINEAR + 3
    got, want = G[:, cols] + 1.0, lower[:, cols] + 1.0  # max |jerk| / limit
    err = np.abs(got - want) / (EXACT * want + 2e-9)
    i, c = np.unravel_index(np.argmax(err), err.shape)
    assert err[i, c] <= 1.0, (f"{what}: jerk of {JOINT_NAMES[LINEAR[c]]} in row {i} is {got[i, c]!r} x its limit, "
                              f"dense {want[i, c]!r}")


def generous_travel(start, goal, d2):
    """Per-joint travel (8,) wide enough for the move (the constructor refuses a move longer
    than 2 x travel), at least the paper's."""
    q = R.joints_of_pose(np.vstack([start, goal]), d2)
    return tuple(np.maximum(np.tile([600.0, 50.0, 50.0, 15.0], 2), 0.75 * np.abs(q[1] - q[0]) + 1.0))


# --------------------------------------------------------------------- 1. certified, every mode
CONFIG = dict(
    pos=st.tuples(st.floats(700, 800), st.floats(-50, 50), st.floats(-1500, -1300)),
    att=st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(170, 190)),
    move=st.tuples(st.floats(-100, 100), st.floats(-100, 100), st.floats(-300, 300), st.floats(-30, 30),
                   st.floats(-30, 30), st.floats(-10, 10)),
    log_d2=st.floats(2.0, 4.0),
    log_jerk=st.lists(st.floats(-1.0, 4.0), min_size=8, max_size=8),
    per_joint=st.booleans(),
    log_lo=st.floats(-1.0, 3.0),
    ratio=st.floats(1.2, 10.0),
    seed=st.integers(0, 2**32 - 1),
    joint=st.sampled_from([4, 5, 6]),
    eps=st.floats(-0.002, 0.002),
)
"""A configuration: start, attitude moves of tens of degrees, D2 from 100 mm to 10 m, jerk
limits from 0.1 to 1e4 (4 for both arms, or 8), interval bounds from 0.1 s to hours, and a
seed for the candidates."""
ALL_MODE_FAMILIES = (2,) if settings.default.max_examples <= 25 else tuple(range(1, 7))
"""Families (n_control) checked in every mode: one by default (the plan test's), as the
"taylor" and "adaptive" kernels take ~45 s to compile per family and ~9 s to trace and load
from the persistent cache; every family from 1 to 6 under ``--hypothesis-profile thorough``.
The bound mode is checked in more families: :data:`BOUND_FAMILIES`."""
BOUND_FAMILIES = (1, 2, 6) if settings.default.max_examples <= 25 else tuple(range(1, 7))
"""Families checked in the bound mode: the smallest, the every-mode family and a larger one
by default (each new family compiles two kernels); every family from 1 to 6 under
``--hypothesis-profile thorough``. The paper's family (5) with jerk limits is checked by
:func:`test_linear_joints_jerk_is_exact_in_bound_mode`."""
CASE = dict(pos=(760.0, -20.0, -1400.0), att=(5.0, -3.0, 185.0), move=(20.0, 20.0, 100.0, 30.0, -30.0, 5.0),
            log_d2=math.log10(2000.0), log_jerk=[1.0, 1.0, 0.0, 1.0] * 2, per_joint=False, log_lo=0.0, ratio=4.0,
            seed=1, joint=5, eps=0.0)


def check_configuration(modes, n_control, pos, att, move, log_d2, log_jerk, per_joint, log_lo, ratio, seed, joint,
                        eps):
    """Random candidates of the box and near-limit ones (a candidate's intervals scaled so
    that a right arm's jerk, a linear joint's jerk or a right arm's acceleration sits at its
    limit): every one of the 32 columns at or above the dense maximum in every mode of
    ``modes``, screened or not; the linear joints' jerk columns equal to it."""
    start = tuple(float(v) for v in (*pos, *att))
    goal = tuple(float(a + b) for a, b in zip(start, move))
    d2 = float(10.0 ** log_d2)
    lo = float(10.0 ** log_lo)
    jerk = tuple(float(10.0 ** v) for v in (log_jerk if per_joint else log_jerk[:4]))
    kw = dict(start=start, goal=goal, arm_distance=d2, interval_bounds=(lo, lo * ratio),
              travel=generous_travel(start, goal, d2), jerk=jerk, jerk_nodes=JERK_NODES, n_control=n_control)
    problems = {m: DockingProblem(**kw, right_arm=m) for m in modes}
    p = next(iter(problems.values()))
    assert p.n_con == 32 and np.asarray(p.limits).shape == (8, 4)
    np.testing.assert_array_equal(np.asarray(p.limits)[:, 3], np.array(jerk if per_joint else jerk * 2))
    x, y = np.random.default_rng(seed).uniform(p.lower, p.upper, (2, p.n_var))
    first = dense(p, x[None], N_PROPERTY)
    m = first[0].reshape(8, 4) + 1.0  # max |quantity| / limit
    lin = LINEAR[np.argmax(m[LINEAR, 3])]
    s_rows = [np.cbrt(m[joint, 3] / (1.0 + eps)), np.cbrt(m[lin, 3]), np.sqrt(m[joint, 2] / (1.0 + eps))]
    X = np.stack([x, y] + [scaled(x, s) if s > 1e-12 else y for s in s_rows])
    lower = np.concatenate([first, dense(p, X[1:], N_PROPERTY)])
    for mode, q in problems.items():
        for screen in (True, False):
            F, G = q.evaluate(X, screen=screen)
            what = f"{mode} (screen={screen}); {kw}"
            assert_certified(G, lower, what, X)
            assert_linear_jerk_exact(G, lower, what)


@settings(max_examples=EXAMPLES, deadline=None)
@given(n_control=st.sampled_from(ALL_MODE_FAMILIES), **CONFIG)
@example(n_control=2, **CASE)
def test_every_column_is_certified_in_every_mode(n_control, **cfg):
    check_configuration(MODES, n_control, **cfg)


@settings(max_examples=EXAMPLES, deadline=None)
@given(n_control=st.sampled_from(BOUND_FAMILIES), **CONFIG)
@example(n_control=6, **CASE)
def test_every_column_is_certified_in_bound_mode_in_every_family(n_control, **cfg):
    check_configuration(("bound",), n_control, **cfg)


# --------------------------------------------------------------------- 2. exact linear jerk
def test_linear_joints_jerk_is_exact_in_bound_mode():
    """The paper's move (tenths of a degree of attitude), per-joint jerk limits (8 distinct
    numbers, so a mix-up of the joint order shows): the jerk columns of the linear joints
    equal the refined dense maximum, screened or not; every column certified."""
    jerk = [3.0, 5.0, 7.0, 11.0, 13.0, 17.0, 19.0, 23.0]
    p = DockingProblem(jerk=jerk, right_arm="bound")
    assert p.right_arm == "bound"
    np.testing.assert_array_equal(np.asarray(p.limits)[:, 3], jerk)
    rng = np.random.default_rng(2)
    X = rng.uniform(p.lower, p.upper, (12, p.n_var))
    m = dense(p, X[:4]).reshape(4, 8, 4) + 1.0
    # near-limit rows: each of the first four rows slowed until its largest linear jerk is at its limit
    X = np.concatenate([X, [scaled(x, np.cbrt(r[LINEAR, 3].max())) for x, r in zip(X[:4], m)]])
    lower = dense(p, X)
    for screen in (True, False):
        F, G = p.evaluate(X, screen=screen)
        assert G.shape == (16, 32)
        assert_certified(G, lower, f"bound (screen={screen})", X)
        assert_linear_jerk_exact(G, lower, f"bound (screen={screen})")
        np.testing.assert_allclose(G[12:, 4 * LINEAR + 3].max(1), 1e-9, atol=2e-6)  # at the limit, as scaled


# --------------------------------------------------------------------- 3. nothing else changes
def test_without_jerk_limits_nothing_changes():
    plain, limited = DockingProblem(right_arm="bound"), DockingProblem(right_arm="bound", jerk=[10, 10, 1, 10])
    assert plain.jerk is None and plain.n_con == 24 and np.asarray(plain.limits).shape == (8, 3)
    assert kind_names(plain) == KINDS[:3] and kind_names(limited) == KINDS
    assert plain.column_names == [f"{j} {k}" for j in JOINT_NAMES for k in KINDS[:3]]
    assert limited.n_con == 32 and limited.column_names == [f"{j} {k}" for j in JOINT_NAMES for k in KINDS]
    np.testing.assert_array_equal(np.asarray(limited.limits)[:, :3], np.asarray(plain.limits))
    np.testing.assert_array_equal(np.asarray(limited.limits)[:, 3], [10, 10, 1, 10] * 2)
    # caches keyed on the identity keep the two apart, and those of problems without jerk limits stay valid
    assert plain.identity() != limited.identity() and "jerk" not in DockingProblem().identity()
    X = np.random.default_rng(3).uniform(plain.lower, plain.upper, (16, plain.n_var))
    for screen in (True, False):
        F0, G0 = plain.evaluate(X, screen=screen)
        F1, G1 = limited.evaluate(X, screen=screen)
        assert G0.shape == (16, 24) and G1.shape == (16, 32)
        np.testing.assert_array_equal(F1, F0)
        np.testing.assert_array_equal(G1.reshape(16, 8, 4)[:, :, :3].reshape(16, 24), G0,
                                      err_msg=f"screen={screen}")


# --------------------------------------------------------------------- 4. bad input
@pytest.mark.parametrize("jerk", [[1, 2, 3], [1] * 5, [1] * 9, [], [0, 1, 1, 1], [1, 1, 1, -1], [1] * 7 + [0],
                                  [float("nan"), 1, 1, 1], [1, float("inf"), 1, 1], [-float("inf")] * 8,
                                  "fast", [[1, 1, 1, 1]], [True, 1, 1, 1]])
def test_bad_jerk_limits_are_refused_naming_them(jerk):
    with pytest.raises(ValueError, match="jerk"):
        DockingProblem(jerk=jerk)


# --------------------------------------------------------------------- 5. limits files
def test_limits_file_takes_jerk(tmp_path):
    f = tmp_path / "limits.toml"
    f.write_text("velocity = [400, 25, 2.5, 6.8]\njerk = [10, 10, 1.5, 10]\n")
    data = load_limits(f)
    assert data["jerk"] == [10, 10, 1.5, 10]
    p = DockingProblem(**data)
    assert p.n_con == 32
    np.testing.assert_array_equal(np.asarray(p.limits)[:, 3], [10, 10, 1.5, 10] * 2)
    g = tmp_path / "limits.json"
    g.write_text(json.dumps({"jerk": list(range(1, 9))}))
    np.testing.assert_array_equal(np.asarray(DockingProblem(**load_limits(g)).limits)[:, 3], np.arange(1, 9))
    bad = tmp_path / "bad.toml"
    bad.write_text('jerk = "fast"\n')
    with pytest.raises(ValueError, match="jerk"):
        load_limits(bad)


def test_plan_command_refuses_bad_jerk_limits_in_one_line(tmp_path, capsys):
    f = tmp_path / "limits.toml"
    f.write_text("jerk = [10, 0, 1, 10]\n")
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        code = cli.main(["plan", "--limits", str(f), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "jerk" in err and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------- 6. a plan
def test_a_plan_with_jerk_limits_is_certified_by_the_reference():
    # the problem of benchmarks/bench_plan.py's quick form (which then reuses its compiled programs)
    p = DockingProblem(jerk=[10, 10, 1, 10], interval_bounds=(0.05, 30), n_control=2)
    result = plan(p, rate=100.0, weights=(1.0, 0.0), n_front=2, check_sensitivities=False)  # shortest time
    assert result.x.shape == (15,)
    jerk_limits = np.asarray(p.limits)[:, 3]
    sampled = np.asarray(result.samples["jerk"])
    assert sampled.ndim == 2 and sampled.shape[1] == 8 and len(sampled) == len(result.samples["t"])
    assert np.all(np.abs(sampled) <= jerk_limits * (1 + 1e-9)), np.max(np.abs(sampled) / jerk_limits)
    G = p.evaluate(result.x[None], screen=False)[1]
    assert G.shape == (1, 32) and np.all(G <= 0), G.max()
    lower, feasible = R.dense_check(p, result.x[None], n_samples=N_DENSE)
    assert lower.shape == (1, 32) and feasible.all(), lower.max()
    assert_certified(G, lower, "plan", result.x[None])
    assert G.max() > -1e-3  # the shortest time: some limit binds
    # the samples are the reference trajectory's
    t = np.asarray(result.samples["t"])
    np.testing.assert_allclose(sampled, R.joints(result.x, p.start, p.goal, p.arm_distance, t, 3),
                               rtol=1e-9, atol=1e-9 * jerk_limits.max())
    T, jerk = R.reference_objectives(result.x, p.start, p.goal, p.arm_distance)
    assert result.T == pytest.approx(T, rel=1e-9) and result.jerk == pytest.approx(jerk, rel=1e-9)
