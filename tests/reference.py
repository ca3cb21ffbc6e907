"""An independent reference for the docking problem, built from ``docs/conventions.md`` alone.

Nothing here imports ``dockjax``: the trajectory is a ``scipy.interpolate.BSpline``, the
joint derivatives of the right arm follow from an explicit chain rule written with complex
exponentials, the jerk integral is Gauss–Legendre with many nodes per knot span, and the
constraints are found by dense sampling of ``[0, T]`` (every knot included) followed by a
local refinement around the largest sample. Tests compare ``dockjax`` with this module;
later issues call :func:`dense_feasible` "the dense check" to certify optimiser results.

Units: seconds, millimetres, degrees (radians only inside trig calls).
Decision vector (conventions §3): ``x = [h_1..h_6, d_3[0..5], …, d_7[0..5]]`` (36,) in the
paper's family; with n free control points ``[h_1..h_{n+1}, d_1, …, d_n]`` (7n + 1,), so the
number of intervals s of a full vector follows from its length, ``(len + 6) / 7``.
Joint order (conventions §4): ``[d_L1, d_L2, d_L3, θ_L, d_R1, d_R2, d_R3, θ_R]``.
Limits are per arm joint ``(axial, lift, lateral, roll)``, length 4 (both arms) or 8.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial.legendre import leggauss
from scipy.interpolate import BSpline

DEGREE = 5
N_INTERVALS = 6
N_FREE = 5
N_POSE = 6
N_JOINTS = 8
N_VAR = N_INTERVALS + N_FREE * N_POSE
N_CON = 3 * N_JOINTS

# Zero-move box half-margins (conventions §3): 1 mm for positions, 0.01° for angles.
ZERO_MOVE_MARGIN = np.array([1.0, 1.0, 1.0, 0.01, 0.01, 0.01])

__all__ = [
    "knots",
    "control_points",
    "pose_spline",
    "pose_derivatives",
    "joint_derivatives",
    "joints",
    "joints_of_pose",
    "default_home",
    "expand_limits",
    "reference_bounds",
    "reduced_to_full",
    "straight_line_x",
    "reference_objectives",
    "dense_constraints",
    "dense_quantity_maxima",
    "dense_columns",
    "dense_feasible",
    "dense_check",
]


def n_intervals_of(x) -> int:
    """Knot intervals s of a full decision vector of length 7s − 6."""
    size = np.asarray(x).shape[-1]
    assert (size + 6) % 7 == 0, size
    return (size + 6) // 7


def _as_pose(p) -> np.ndarray:
    """A pose (6,), or the pose of a state (3, 6) (see :func:`control_points`)."""
    p = np.asarray(p, dtype=np.float64)
    p = p[0] if p.shape == (3, N_POSE) else p.reshape(-1)
    assert p.shape == (N_POSE,), p.shape
    return p


def _end_points(u, state, at_end: bool) -> np.ndarray:
    """The two control points next to an end (in the order away from it) that give the
    state ``(pose, velocity, acceleration)`` (3, 6) there: the first and second derivatives
    at the end are linear in the three end control points, with weights the B-spline basis
    functions' derivatives, evaluated by SciPy and solved for the two unknowns."""
    n = len(u) - DEGREE - 1
    idx = [n - 1, n - 2, n - 3] if at_end else [0, 1, 2]
    t = u[-1] if at_end else u[0]
    D = np.array([[BSpline(u, np.eye(n)[i], DEGREE)(t, nu=k) for i in idx] for k in (1, 2)])  # (2, 3)
    pose, vel, acc = np.asarray(state, dtype=np.float64)
    return np.linalg.solve(D[:, 1:], np.stack([vel, acc]) - np.outer(D[:, 0], pose))


def knots(h) -> np.ndarray:
    """Clamped knot vector ``[0]*6, t_1..t_5, [T]*6`` (17,) from the intervals h (6,)."""
    h = np.asarray(h, dtype=np.float64)
    t = np.cumsum(h)
    return np.concatenate([np.zeros(DEGREE + 1), t[:-1], np.full(DEGREE + 1, t[-1])])


def control_points(x, start, goal) -> np.ndarray:
    """Control points (n + 6, 6): start ×3, the n free points, goal ×3 (``d_0..d_10`` for n = 5).

    ``start`` or ``goal`` may be a state (3, 6), pose, velocity and acceleration: then the
    two control points next to that end give those derivatives (:func:`_end_points`)."""
    x = np.asarray(x, dtype=np.float64)
    s = n_intervals_of(x)
    free = x[s:].reshape(s - 1, N_POSE)
    ends = []
    for p, at_end in ((start, False), (goal, True)):
        p = np.asarray(p, dtype=np.float64)
        if p.shape == (3, N_POSE):
            inner = _end_points(knots(x[:s]), p, at_end)
            ends.append(np.vstack([p[0], inner]) if not at_end else np.vstack([inner[::-1], p[0]]))
        else:
            ends.append(np.tile(_as_pose(p), (3, 1)))
    return np.vstack([ends[0], free, ends[1]])


def pose_spline(x, start, goal) -> BSpline:
    """The pose trajectory as one vector-valued degree-5 ``scipy`` B-spline."""
    x = np.asarray(x, dtype=np.float64)
    return BSpline(knots(x[:n_intervals_of(x)]), control_points(x, start, goal), DEGREE)


def pose_derivatives(x, start, goal, t, max_order: int = 3) -> np.ndarray:
    """Pose and its time derivatives at t: (max_order + 1, m, 6)."""
    spl = pose_spline(x, start, goal)
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    out = [spl(t)]
    for k in range(1, max_order + 1):
        out.append(spl.derivative(k)(t))
    return np.stack(out)


def _exp_derivatives(phi: np.ndarray) -> np.ndarray:
    """Derivatives 0..3 of ``f = exp(i φ(t))`` given φ and its derivatives (4, m), radians.

    f' = i φ' f;  f'' = (i φ'' − φ'²) f;  f''' = (i φ''' − 3 φ' φ'' − i φ'³) f.
    """
    p0, p1, p2, p3 = phi
    f = np.exp(1j * p0)
    return np.stack(
        [
            f,
            1j * p1 * f,
            (1j * p2 - p1**2) * f,
            (1j * p3 - 3.0 * p1 * p2 - 1j * p1**3) * f,
        ]
    )


def _axis_derivatives(alpha_deg: np.ndarray, beta_deg: np.ndarray) -> np.ndarray:
    """Cabin axis ``u = (cos α sin β, sin α, cos α cos β)`` and derivatives 0..3: (4, m, 3).

    alpha_deg, beta_deg: (4, m), the angle (°) and its time derivatives (°/s^k).
    Written with the product-to-sum identities
    ``cos α sin β = ½[sin(β+α) + sin(β−α)]``, ``cos α cos β = ½[cos(β+α) + cos(β−α)]``,
    so every component is the real or imaginary part of ``exp(i φ(t))`` for a φ linear in α, β.
    """
    a = np.deg2rad(alpha_deg)
    b = np.deg2rad(beta_deg)
    e_a = _exp_derivatives(a)
    e_plus = _exp_derivatives(b + a)
    e_minus = _exp_derivatives(b - a)
    ux = 0.5 * (e_plus.imag + e_minus.imag)
    uy = e_a.imag
    uz = 0.5 * (e_plus.real + e_minus.real)
    return np.stack([ux, uy, uz], axis=-1)


def _joints_from_pose_derivatives(pd: np.ndarray, arm_distance) -> np.ndarray:
    """Joint values and derivatives (K, m, 8) from pose derivatives (K, m, 6), K ≤ 4.

    ``arm_distance``: D_2, or the offsets (S,) of a cabin's S supports along its axis (the
    first 0): then (K, m, 4 S), support by support, each support after the first with the
    right arm's joints at its own end ``K_L + o u`` (conventions §4)."""
    n = pd.shape[0]
    full = np.zeros((4,) + pd.shape[1:])
    full[:n] = pd
    u = _axis_derivatives(full[:, :, 3], full[:, :, 4])[:n]  # (n, m, 3)
    x, y, z, g = pd[:, :, 0], pd[:, :, 1], pd[:, :, 2], pd[:, :, 5]
    out = [-z, y, -x, g]
    offsets = [float(arm_distance)] if np.ndim(arm_distance) == 0 else [float(o) for o in arm_distance][1:]
    for o in offsets:
        right = pd[:, :, :3] + o * u  # this support's end and its derivatives (task XYZ)
        # The constant parts of the end enter only derivative 0, which `right` already carries.
        xr, yr, zr = right[:, :, 0], right[:, :, 1], right[:, :, 2]
        out += [zr, yr, -xr, -g]
    return np.stack(out, axis=-1)


def joints_of_pose(pose, arm_distance: float) -> np.ndarray:
    """Inverse kinematics (conventions §4) of poses (..., 6) → joints (..., 8)."""
    pose = np.asarray(pose, dtype=np.float64)
    flat = pose.reshape(1, -1, N_POSE)
    return _joints_from_pose_derivatives(flat, arm_distance)[0].reshape(pose.shape[:-1] + (-1,))


def joint_derivatives(x, start, goal, arm_distance: float, t) -> np.ndarray:
    """Joints and their 1st, 2nd, 3rd time derivatives at t: (4, m, 8)."""
    pd = pose_derivatives(x, start, goal, t, 3)
    return _joints_from_pose_derivatives(pd, arm_distance)


def joints(x, start, goal, arm_distance: float, t, derivative: int = 0) -> np.ndarray:
    """Joint values (derivative 0) or a time derivative (1..3) at t: (m, 8)."""
    return joint_derivatives(x, start, goal, arm_distance, t)[derivative]


def default_home(start, goal, arm_distance: float) -> np.ndarray:
    """Home of each joint: midpoint of its start and goal values (8,)."""
    q = joints_of_pose(np.vstack([_as_pose(start), _as_pose(goal)]), arm_distance)
    return 0.5 * (q[0] + q[1])


def expand_limits(travel, velocity, acceleration) -> np.ndarray:
    """Limits (8, 3) ``[travel, velocity, acceleration]`` per joint from length-4 or -8 inputs."""
    cols = []
    for v in (travel, velocity, acceleration):
        v = np.asarray(v, dtype=np.float64).reshape(-1)
        if v.shape == (4,):
            v = np.tile(v, 2)
        assert v.shape == (8,), v.shape
        cols.append(v)
    return np.stack(cols, axis=1)


def reference_bounds(start, goal, interval_bounds=(3.5, 10.0), margin: float = 0.1, n_free: int = N_FREE):
    """Box ``(lower, upper)`` (7 n_free + 1,) each (36 in the paper), per conventions §3."""
    start, goal = _as_pose(start), _as_pose(goal)
    delta = goal - start
    m = np.where(delta == 0.0, ZERO_MOVE_MARGIN, margin * np.abs(delta))
    lo_p = np.minimum(start, goal) - m
    hi_p = np.maximum(start, goal) + m
    lo = np.concatenate([np.full(n_free + 1, float(interval_bounds[0])), np.tile(lo_p, n_free)])
    hi = np.concatenate([np.full(n_free + 1, float(interval_bounds[1])), np.tile(hi_p, n_free)])
    return lo, hi


def reduced_to_full(h, start, goal) -> np.ndarray:
    """Full x of the reduced setting from its s intervals h: the s − 1 free points at
    start + i/s (goal − start), i = 1..s − 1 (the paper: s = 6, x (36,))."""
    start, goal = _as_pose(start), _as_pose(goal)
    h = np.asarray(h, dtype=np.float64).reshape(-1)
    i = np.arange(1, len(h))[:, None] / float(len(h))
    free = start + i * (goal - start)
    return np.concatenate([h, free.ravel()])


def straight_line_x(start, goal, h=(10.0,) * 6) -> np.ndarray:
    """A decision vector with the interior points on the straight line (same as reduced)."""
    return reduced_to_full(h, start, goal)


def reference_objectives(x, start, goal, arm_distance: float, nodes: int = 20):
    """``(T, jerk)``: T = Σ h; jerk = Σ_j sqrt((1/T) ∫_0^T q_j'''(t)² dt) (conventions §5).

    The integral is Gauss–Legendre with ``nodes`` nodes per knot span (exact for the
    polynomial joints, converged to round-off for the right arm's trig joints).
    """
    x = np.asarray(x, dtype=np.float64)
    h = x[:n_intervals_of(x)]
    T = float(np.sum(h))
    edges = np.concatenate([[0.0], np.cumsum(h)])
    edges[-1] = knots(h)[-1]
    xi, wi = leggauss(nodes)
    a, b = edges[:-1, None], edges[1:, None]
    t = (0.5 * (b - a) * xi + 0.5 * (a + b)).ravel()
    w = (0.5 * (b - a) * wi).ravel()
    jerk_q = joint_derivatives(x, start, goal, arm_distance, t)[3]  # (m, 8)
    integral = np.sum(w[:, None] * jerk_q**2, axis=0)
    return T, float(np.sum(np.sqrt(integral / T)))


def dense_quantity_maxima(
    x, start, goal, arm_distance: float, home=None, n_samples: int = 20001, refine: int = 201, n_kinds: int = 3
) -> np.ndarray:
    """Dense maxima (8, n_kinds) of ``[|q − home|, |q'|, |q''|]``, and with ``n_kinds=4``
    also of the jerk ``|q'''|``, over t ∈ [0, T].

    Samples ``n_samples`` evenly spaced instants plus every knot; then, per column,
    resamples ``refine`` points within one sample spacing either side of the largest sample
    (the result never exceeds the true maximum and is within round-off of it).
    """
    assert n_kinds in (3, 4), n_kinds
    x = np.asarray(x, dtype=np.float64)
    kn = knots(x[:n_intervals_of(x)])
    T = kn[-1]
    t = np.union1d(np.linspace(0.0, T, int(n_samples)), kn)
    if home is None:
        home = default_home(start, goal, arm_distance)
    home = np.asarray(home, dtype=np.float64).reshape(-1)

    def quantities(tt):
        qd = joint_derivatives(x, start, goal, arm_distance, tt)
        # (m, 8, n_kinds): |q − home|, |q'|, |q''| (and the jerk)
        return np.stack([np.abs(qd[0] - home)] + [np.abs(qd[k]) for k in range(1, n_kinds)], axis=-1)

    vals = quantities(t)
    arg = np.argmax(vals, axis=0)  # (8, n_kinds)
    best = np.max(vals, axis=0)
    if refine:
        spacing = T / (int(n_samples) - 1)
        centres = np.unique(t[arg.ravel()])
        for c in centres:
            tt = np.clip(np.linspace(c - spacing, c + spacing, int(refine)), 0.0, T)
            best = np.maximum(best, np.max(quantities(tt), axis=0))
    return best


def dense_columns(x, start, goal, arm_distance: float, limits, home=None, n_samples: int = 20001) -> np.ndarray:
    """G (8 K,) by the dense check for a limit table ``limits`` (8, K): K = 3 (travel,
    velocity, acceleration) or 4 (and jerk). Column ``K j + k`` = max_t |quantity| / limit − 1
    (joint-major; travel about ``home``)."""
    limits = np.asarray(limits, dtype=np.float64)
    assert limits.ndim == 2 and limits.shape[1] in (3, 4) and limits.shape[0] % 4 == 0, limits.shape
    maxima = dense_quantity_maxima(x, start, goal, arm_distance, home=home, n_samples=n_samples,
                                   n_kinds=limits.shape[1])
    return (maxima / limits - 1.0).reshape(-1)


def dense_constraints(
    x,
    start,
    goal,
    arm_distance: float,
    travel,
    velocity,
    acceleration,
    home=None,
    n_samples: int = 20001,
) -> np.ndarray:
    """G (24,) per conventions §6 by the dense check: column ``3j + k`` = max_t |quantity|/limit − 1.

    travel/velocity/acceleration: length 4 (per arm joint axial, lift, lateral, roll; the
    same for both arms) or 8 (per joint). home: (8,) or None (midpoint of start and goal).
    """
    limits = expand_limits(travel, velocity, acceleration)
    maxima = dense_quantity_maxima(x, start, goal, arm_distance, home=home, n_samples=n_samples)
    return (maxima / limits - 1.0).reshape(N_CON)


def dense_feasible(
    x,
    start,
    goal,
    arm_distance: float,
    travel,
    velocity,
    acceleration,
    home=None,
    n_samples: int = 20001,
    tol: float = 0.0,
) -> bool:
    """True when every column of :func:`dense_constraints` is ≤ tol (the dense check)."""
    g = dense_constraints(
        x, start, goal, arm_distance, travel, velocity, acceleration, home=home, n_samples=n_samples
    )
    return bool(np.all(g <= tol))


def dense_check(problem, X, n_samples: int = 20001):
    """The dense check of a whole population for any problem-like object.

    ``problem`` needs ``start``, ``goal``, ``arm_distance`` (or ``supports``, the offsets of
    a cabin's supports), ``limits`` (8 or 4 per support, K: 3, or 4 with jerk limits),
    ``home`` (8,) and ``n_var``; nothing of it is called, so no dockjax code
    runs. X: (n, n_var), in the reduced setting (n_var 6) the interior points are put on the
    line. Returns ``(G (n, 8 K), feasible (n,) bool)`` (8 K = 24 without jerk limits).
    """
    X = np.atleast_2d(np.asarray(X, dtype=np.float64))
    limits = np.asarray(problem.limits, dtype=np.float64)
    start = np.asarray(problem.start, dtype=np.float64)
    goal = np.asarray(problem.goal, dtype=np.float64)
    if getattr(problem, "start_velocity", None) is not None:  # the end states (3, 6)
        start = np.stack([start, problem.start_velocity, problem.start_acceleration])
        goal = np.stack([goal, problem.goal_velocity, problem.goal_acceleration])
    G = []
    for x in X:
        if getattr(problem, "reduced", x.shape == (N_INTERVALS,)):
            x = reduced_to_full(x, start, goal)
        ends = getattr(problem, "supports", None)
        ends = float(problem.arm_distance) if ends is None else np.asarray(ends, np.float64)
        G.append(dense_columns(x, start, goal, ends, limits, home=np.asarray(problem.home), n_samples=n_samples))
    G = np.array(G).reshape(len(X), limits.size)
    return G, np.all(G <= 0.0, axis=1)
