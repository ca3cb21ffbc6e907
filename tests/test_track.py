"""Servo tracking (dockjax.track): the simulated loop against an independent SciPy/NumPy
reference, exact cases worked by hand, the stability check, validation and the paper's moves.

The references here use no dockjax code: the plant is discretised by
``scipy.signal.cont2discrete`` (zero-order hold) or integrated by ``scipy.integrate.solve_ivp``,
and the controller is a plain Python loop written from the equations of the module docstring.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import cont2discrete, impulse

from dockjax import DockingProblem, config
from dockjax.plots import plot_tracking
from dockjax.solve import straight_line
from dockjax.track import (
    PAPER_ERRORS,
    PAPER_JOINTS,
    PAPER_MOVES,
    AxisModel,
    TrackResult,
    _loop_jit,
    check_model,
    closed_loop_poles,
    gains,
    plant_step,
    simulate,
    track,
)

RATE = 1000.0
EXPLICIT = dict(kp=4000.0, ki=8.0e4, kd=90.0)  # gains given, so the reference does not need gains()


def quintic(rate, T=2.0, L=10.0, x0=100.0, m=None):
    """A rest-to-rest quintic move of L over T, sampled at rate: t (m,), r, v, a (m, 1)."""
    m = m or int(round(T * rate)) + 1
    t = np.arange(m) / rate
    s = np.clip(t / T, 0, 1)
    r = x0 + L * (10 * s**3 - 15 * s**4 + 6 * s**5)
    v = L / T * (30 * s**2 - 60 * s**3 + 30 * s**4)
    a = L / T**2 * (60 * s - 180 * s**2 + 120 * s**3)
    return t, r[:, None], v[:, None], a[:, None]


def samples_of(t, r, v, a):
    return dict(t=t, position=r, velocity=v, acceleration=a)


def reference_loop(r, v, a, *, m, b, m_hat, b_hat, kp, ki, kd, ka=1.0, kv=1.0, tau=0.0, h=1e-3, x_init=None):
    """The linear loop (no friction, exact encoder) by ZOH discretisation and a plain loop.
    r, v, a: (n,) reference at the ticks. Returns the plant position at the ticks (n,)."""
    A = np.array([[0.0, 1.0], [0.0, -b / m]])
    B = np.array([[0.0], [1.0 / m]])
    Ad, Bd, *_ = cont2discrete((A, B, np.eye(2), np.zeros((2, 1))), h, method="zoh")
    state = np.array([r[0] if x_init is None else x_init, 0.0])
    e_prev, edot, integral = r[0] - state[0], 0.0, 0.0
    alpha = 1.0 if tau == 0 else 1.0 - math.exp(-h / tau)
    out = np.empty(len(r))
    for k in range(len(r)):
        out[k] = state[0]
        e = r[k] - state[0]
        edot = edot + alpha * ((0.0 if k == 0 else (e - e_prev) / h) - edot)
        integral += h * e
        u = m_hat * ka * a[k] + b_hat * kv * v[k] + kp * e + ki * integral + kd * edot
        state = Ad @ state + Bd[:, 0] * u
        e_prev = e
    return out


# -- the linear loop against the independent reference ---------------------------------------


@pytest.mark.parametrize("b, tau, mass_error", [(2.0, 0.0, 0.05), (0.0, 0.0, -0.1), (5.0, 0.003, 0.2)])
def test_linear_loop_matches_scipy_zoh_reference(b, tau, mass_error):
    t, r, v, a = quintic(RATE)
    model = AxisModel(mass=1.5, damping=b, friction=0.0, resolution=0.0, mass_error=mass_error, damping_error=0.05,
                      velocity_filter=tau, **EXPLICIT)
    out = simulate(samples_of(t, r, v, a), model, RATE)
    ref = reference_loop(r[:, 0], v[:, 0], a[:, 0], m=1.5, b=b, m_hat=1.5 * (1 + mass_error), b_hat=b * 1.05,
                         tau=tau, **EXPLICIT)
    err_ref = np.max(np.abs(ref - r[:, 0]))
    assert err_ref > 1e-7  # the mismatch makes a real tracking error to compare
    # positions agree to 1e-9 of the tracking error itself (far tighter than 1e-9 of the position)
    assert np.max(np.abs(out["position"][:, 0] - ref)) <= 1e-9 * err_ref + 1e-12


def test_linear_loop_with_last_short_step_and_eight_joints():
    """A Trajectory-like time grid (last step shorter) and joints vectorised: each column
    equals its own one-joint run."""
    t, r, v, a = quintic(RATE, T=1.5)
    t = np.append(t, t[-1] + 0.4e-3)
    r, v, a = (np.concatenate([z, z[-1:]]) for z in (r, v, a))
    R = r * np.linspace(0.5, 2.0, 8)
    V, A = v * np.linspace(0.5, 2.0, 8), a * np.linspace(0.5, 2.0, 8)
    friction = np.array([0.0, 1.0, 2.0, 0.5, 0.0, 3.0, 1.0, 0.1])
    out8 = simulate(samples_of(t, R, V, A), AxisModel(friction=friction), RATE)
    for j in (0, 1, 5):
        one = simulate(samples_of(t, R[:, j:j + 1], V[:, j:j + 1], A[:, j:j + 1]),
                       AxisModel(friction=float(friction[j])), RATE)
        np.testing.assert_allclose(out8["position"][:, j], one["position"][:, 0], rtol=1e-14, atol=0)
    # and the friction was each joint's own
    free = simulate(samples_of(t, R[:, 1:2], V[:, 1:2], A[:, 1:2]), AxisModel(friction=0.0), RATE)
    assert np.max(np.abs(free["position"][:, 0] - out8["position"][:, 1])) > 1e-7


def test_encoder_is_incremental_from_the_initial_position():
    """Counts of q from the start: a joint at rest off the absolute grid stays exactly at
    rest, and a moving joint's measurement is a whole number of counts from the start."""
    t = np.arange(3000) / RATE
    x0 = 12.3456789012
    still = np.full((len(t), 1), x0)
    zero = np.zeros_like(still)
    out = simulate(samples_of(t, still, zero, zero), AxisModel(), RATE)
    assert np.all(out["position"] == x0) and np.all(out["velocity"] == 0)
    t, r, v, a = quintic(RATE, x0=x0)
    out = simulate(samples_of(t, r, v, a), AxisModel(resolution=1e-3), RATE)
    counts = (out["measured_position"][:, 0] - x0) / 1e-3
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.max(np.abs(out["measured_position"][:, 0] - out["position"][:, 0])) <= 0.5e-3 * (1 + 1e-9)
    assert np.ptp(counts) > 9000


# -- feed-forward ----------------------------------------------------------------------------


def test_perfect_feedforward_on_a_plant_consistent_reference_is_exact():
    """A reference made by the plant itself under a held input (exact ZOH): with the
    controller's model equal to the plant, the feed-forward alone reproduces it."""
    m, b, h = 1.2, 3.0, 1e-3
    Ad, Bd, *_ = cont2discrete((np.array([[0, 1], [0, -b / m]]), np.array([[0], [1 / m]]), np.eye(2),
                                np.zeros((2, 1))), h, method="zoh")
    k = np.arange(1500)
    u = 40 * np.sin(2 * np.pi * k / 1500) * np.exp(-k / 900)
    xs = np.empty((len(k), 2))
    s = np.array([50.0, 0.0])
    for i in k:
        xs[i] = s
        s = Ad @ s + Bd[:, 0] * u[i]
    acc = (u - b * xs[:, 1]) / m  # so that m a + b v = u at every tick
    model = AxisModel(mass=m, damping=b, friction=0.0, resolution=0.0, mass_error=0.0, damping_error=0.0)
    out = simulate(samples_of(k / RATE, xs[:, :1], xs[:, 1:], acc[:, None]), model, RATE)
    assert np.ptp(xs[:, 0]) > 1.0
    assert np.max(np.abs(out["position"][:, 0] - xs[:, 0])) < 1e-10
    assert np.max(np.abs(out["velocity"][:, 0] - xs[:, 1])) < 1e-9


def _disturbance_l1(model):
    """∫|g| of the continuous loop's impulse response from an input disturbance (acceleration
    units) to the position error: g = s / (m s³ + (b + K_d) s² + K_p s + K_i)."""
    kp, ki, kd = (float(g) for g in gains(model))
    tt = np.linspace(0, 3.0, 60001)
    _, y = impulse(([1.0, 0.0], [model.mass, model.damping + kd, kp, ki]), T=tt)
    return float(np.sum(np.abs(y)) * (tt[1] - tt[0]))


def test_feedforward_errors_small_when_perfect_and_bounded_when_mismatched():
    """Same gains, exact encoder, no friction: with a perfect model only the hold of the
    feed-forward over a tick errs; a 5 % model error adds the response to the disturbance
    d = (m̂ − m) a + (b̂ − b) v, bounded by ||g||_1 max|d| (superposition)."""
    fixed = dict(zip(("kp", "ki", "kd"), (float(g) for g in gains(AxisModel()))), friction=0.0, resolution=0.0)
    perfect_model = AxisModel(mass_error=0.0, damping_error=0.0, **fixed)
    model = AxisModel(**fixed)  # 5 % errors
    l1 = _disturbance_l1(model)
    t, r, v, a = quintic(RATE)
    e_perfect = track(samples_of(t, r, v, a), perfect_model, RATE).max_position_error[0]
    e_mismatch = track(samples_of(t, r, v, a), model, RATE).max_position_error[0]
    # the held feed-forward misses the acceleration by at most m |jerk| h + b |a| h in a tick
    jerk_max, acc_max = 60 * 10.0 / 2.0**3, 10 * np.sqrt(3) / 3 * 10.0 / 2.0**2
    assert 0 < e_perfect <= 1.05 * l1 * (model.mass * jerk_max + model.damping * acc_max) / RATE
    assert e_perfect < 1e-5  # on a 10 mm move
    # that part halves when the rate doubles (first order in h)
    t2, r2, v2, a2 = quintic(2 * RATE)
    e_perfect_2 = track(samples_of(t2, r2, v2, a2), perfect_model, 2 * RATE).max_position_error[0]
    assert 1.7 < e_perfect / e_perfect_2 < 2.3
    d = 0.05 * model.mass * np.abs(a[:, 0]) + 0.05 * model.damping * np.abs(v[:, 0])
    assert 3 * e_perfect < e_mismatch <= 1.05 * l1 * np.max(d) + e_perfect


# -- the plant with Coulomb friction ---------------------------------------------------------


def test_plant_step_hand_cases():
    import jax

    with jax.enable_x64(True):
        step = lambda *a: tuple(float(z) for z in plant_step(*a))  # noqa: E731
        # b = 0, slides from 1 to a stop under friction 2: stops at 0.5 s after v²/(2 f_c) = 0.25
        assert step(0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 2.0) == pytest.approx((0.25, 0.0), abs=1e-15)
        # at rest, |u| <= f_c: sticks
        assert step(3.0, 0.0, 1.5, 1.0, 1.0, 0.0, 2.0) == (3.0, 0.0)
        assert step(3.0, 0.0, -2.0, 1.0, 1.0, 4.0, 2.0) == (3.0, 0.0)
        # breakaway, b = 0: (u − f_c)/m = 0.5 → x = 0.25 dt², v = 0.5 dt
        assert step(0.0, 0.0, 3.0, 0.2, 2.0, 0.0, 2.0) == pytest.approx((0.01, 0.1), rel=1e-14)
        # no friction, b = 0: uniform acceleration
        assert step(1.0, 2.0, 4.0, 0.5, 2.0, 0.0, 0.0) == pytest.approx((1.0 + 1.0 + 0.25, 3.0), rel=1e-14)


@pytest.mark.parametrize("v0, u", [(1.0, -5.0), (-2.0, 0.5), (0.3, 2.0), (1.0, -0.5)])
def test_plant_step_matches_solve_ivp_through_a_reversal(v0, u):
    """m = 1.3, b = 3, f_c = 1: a reversal (1, −5), a stop and stick (−2, 0.5), a slide on
    (0.3, 2), a stop and stick (1, −0.5); reference by RK45 with a stop event."""
    import jax

    m, b, fc, dt = 1.3, 3.0, 1.0, 1.0

    def rhs(sign):
        return lambda t, s: [s[1], (u - b * s[1] - fc * sign) / m]

    stop = lambda t, s: s[1]  # noqa: E731
    stop.terminal = True
    tol = dict(rtol=1e-12, atol=1e-14)
    sol = solve_ivp(rhs(np.sign(v0)), (0, dt), [0.0, v0], events=stop, **tol)
    x, v = sol.y[:, -1]
    if sol.status == 1:  # stopped: sticks or slides the other way
        v = 0.0
        if abs(u) > fc:
            sol = solve_ivp(rhs(np.sign(u)), (sol.t[-1], dt), [x, 0.0], **tol)
            x, v = sol.y[:, -1]
    with jax.enable_x64(True):
        got = [float(z) for z in plant_step(0.0, v0, u, dt, m, b, fc)]
    assert got == pytest.approx([x, v], rel=1e-9, abs=1e-12)


# -- gains and stability ---------------------------------------------------------------------


def test_default_gains_place_the_continuous_poles():
    model = AxisModel(mass=2.0, damping=1.0, bandwidth=8.0, damping_ratio=0.6)
    kp, ki, kd = (float(g) for g in gains(model))
    m_hat, b_hat = 2.0 * 1.05, 1.0 * 1.05
    roots = np.sort_complex(np.roots([m_hat, b_hat + kd, kp, ki]))
    w = 2 * np.pi * 8.0
    want = np.sort_complex(np.array([-w, w * (-0.6 + 1j * 0.8), w * (-0.6 - 1j * 0.8)]))
    np.testing.assert_allclose(roots, want, rtol=1e-9)


@pytest.mark.parametrize("bandwidth", [10.0, 40.0, 100.0])
def test_closed_loop_poles_give_the_growth_of_the_reference_loop(bandwidth):
    """The largest |z| equals the decay (or growth) rate per tick of the reference loop's
    free response."""
    model = AxisModel(bandwidth=bandwidth, friction=0.0, resolution=0.0)
    rho = np.max(np.abs(closed_loop_poles(model, RATE)))
    kp, ki, kd = (float(g) for g in gains(model))
    n = 1500
    zero = np.zeros(n)
    x = reference_loop(zero, zero, zero, m=1.0, b=2.0, m_hat=1.05, b_hat=2.1, kp=kp, ki=ki, kd=kd, x_init=1.0)
    w1, w2 = np.max(np.abs(x[500:900])), np.max(np.abs(x[1000:1400]))
    assert (w2 / w1) ** (1 / 500) == pytest.approx(rho, rel=2e-3)
    if rho >= 1:
        with pytest.raises(ValueError, match=r"unstable at 1000 Hz: largest \|z\| = 1\.\d+"):
            check_model(model, RATE)
    else:
        assert check_model(model, RATE) == pytest.approx(rho)


def test_unstable_gains_are_refused_before_simulating():
    t, r, v, a = quintic(RATE)
    with pytest.raises(ValueError, match="unstable"):
        simulate(samples_of(t, r, v, a), AxisModel(kp=4e6, ki=0.0, kd=0.0), RATE)
    with pytest.raises(ValueError, match="joint d_R1 is unstable"):
        check_model(AxisModel(kd=np.array([100.0] * 4 + [5000.0] + [100.0] * 3)), RATE)


# -- validation ------------------------------------------------------------------------------


@pytest.mark.parametrize("field, value", [
    ("mass", -1.0), ("mass", 0.0), ("damping", -0.1), ("friction", float("nan")), ("kp", -1.0), ("ki", -5.0),
    ("kd", float("inf")), ("ka_ff", -1.0), ("resolution", -1e-4), ("velocity_filter", -0.01), ("bandwidth", 0.0),
    ("mass_error", -1.0), ("mass", [[1.0, 2.0]]),
])
def test_bad_fields_are_named(field, value):
    with pytest.raises(ValueError, match=rf"model\.{field}"):
        check_model(AxisModel(**{field: value}), RATE)


def test_bad_rate_and_shapes_are_refused():
    t, r, v, a = quintic(RATE, T=0.5)
    for rate in (0.0, -1.0, config.MAX_RATE * 1.01, float("nan")):
        with pytest.raises(ValueError, match="rate"):
            check_model(AxisModel(), rate)
        with pytest.raises(ValueError, match="rate"):
            track(samples_of(t, r, v, a), AxisModel(), rate)
    with pytest.raises(ValueError, match="model.kd derived from the bandwidth"):
        check_model(AxisModel(damping=1000.0), RATE)
    with pytest.raises(ValueError, match="different numbers of joints"):
        check_model(AxisModel(mass=[1.0, 1.0], damping=[1.0, 1.0, 1.0]), RATE)
    with pytest.raises(ValueError, match="different numbers of joints"):
        simulate(samples_of(t, r, v, a), AxisModel(mass=[1.0, 1.0]), RATE)
    with pytest.raises(ValueError, match="spaced 1/rate"):
        simulate(samples_of(t, r, v, a), AxisModel(), 2 * RATE)
    with pytest.raises(ValueError, match="lack acceleration"):
        simulate(dict(t=t, position=r, velocity=v), AxisModel(), RATE)


# -- the paper's moves -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def x_move():
    start, goal = PAPER_MOVES["x"]
    problem = DockingProblem(start=start, goal=goal)
    return problem.decode(straight_line(problem, [24.0])[0])


def test_paper_moves_are_valid_problems_driving_the_named_joints():
    for name, (start, goal) in PAPER_MOVES.items():
        problem = DockingProblem(start=start, goal=goal)
        q = problem.decode(straight_line(problem, [24.0])[0]).joints([0.0, 24.0])
        moved = np.flatnonzero(np.abs(q[1] - q[0]) > 1e-9)
        j = PAPER_JOINTS[name]
        assert j in moved and set(moved) == {j, j + 4}  # the left joint and its right-arm twin
        axis = "xyz".index(name)
        assert q[1, j] - q[0, j] == pytest.approx(-(goal[axis] - start[axis]), abs=1e-9)
    assert set(PAPER_ERRORS) == set(PAPER_MOVES)


def test_paper_x_move_tracked_by_the_default_model(x_move, tmp_path):
    result = track(x_move)
    assert isinstance(result, TrackResult)
    m = len(result.t)
    assert m == 24001 and result.position.shape == result.velocity.shape == (m, 8)
    moving = [PAPER_JOINTS["x"], PAPER_JOINTS["x"] + 4]
    still = [j for j in range(8) if j not in moving]
    for e in (result.max_position_error, result.max_velocity_error, result.max_measured_velocity_error):
        assert np.all(np.isfinite(e)) and np.all(e[moving] > 0) and np.all(e[still] < 1e-9)
    # an encoder of 0.1 µm and a 10 Hz loop: errors of the order of counts, far below the move
    assert 1e-6 < result.max_position_error[moving[0]] < 1e-3
    # measured velocity: differencing one count per 1 ms tick is 0.1 mm/s
    assert 0.05 < result.max_measured_velocity_error[moving[0]] < 0.5
    # a second trajectory of another length in the same bucket compiles nothing new
    before = _loop_jit._cache_size()
    other = x_move.problem.decode(straight_line(x_move.problem, [25.0])[0])
    assert len(track(other).t) == 25001 and _loop_jit._cache_size() == before
    path = plot_tracking(result, [PAPER_JOINTS["x"], 0], tmp_path / "x.png", title="X move")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
