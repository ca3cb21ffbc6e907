"""Single-trajectory optimal control by sequential quadratic programming (conventions §3, §5, §6).

Two nonlinear programmes over one decision vector ``x`` (n_var,), both solved by SciPy's
SLSQP with values and Jacobians from one jitted JAX function (float64):

* **shortest time** (:func:`min_time`): minimise ``T(x) = Σ h_k`` subject to the limits;
* **least jerk at a time** (:func:`min_jerk`): minimise the jerk objective (Eq. 25)
  subject to ``T(x) ≤ T_cap`` and the limits.

The limits enter at every critical time (:func:`candidate_limits`): per knot span and
joint, the travel, velocity and acceleration at the span's ends and at the roots of the
next derivative, 15 values, each its own smooth constraint (720 in all). A column whose
maximum is reached at several times (as at a time-optimal solution, where a velocity rides
its limit) is then several smooth constraints rather than one kinked maximum. Their
gradients follow the envelope theorem (the critical times carry no derivative, see
:func:`dockjax.extrema.chain_extrema`); the right arm uses the ``"bound"`` treatment's
remainder, which never understates (conventions §6).

The solver works in the unit box ``x = lower + u (upper − lower)``. Its answer is then
**certified** by :func:`certify_scaling`: the kernel's own columns (never understated in any
right-arm treatment) decide, and a trajectory that misses a rate limit by the solver's
tolerance is slowed by the exact time scaling ``h → s h`` (velocities scale by ``1/s``,
accelerations by ``1/s²``, travel is unchanged), so every returned trajectory is feasible.

The Lagrange multipliers of the active constraints give the sensitivities of the optimum to
each limit (:func:`sensitivities`, the envelope theorem): ``d f*/d L = Σ_i λ_i ∂g_i/∂L``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import lsq_linear, minimize

from . import config, extrema, robot
from .bspline import control_points, insert_knots, poly_derivative, poly_eval, split_counts
from .decoding import spans
from .fusion import materialize
from .kinematics import inverse_kinematics
from .limits import joint_series
from .objectives import cabin_jerk
from .problem import DockingProblem
from .right_arm import linearisation_remainders
from .robot import ATTITUDE_JOINTS, by_kind
from .store import stored_jit

__all__ = ["Solution", "PlanError", "candidate_limits", "critical_times", "straight_line", "least_jerk",
           "least_jerk_front", "kept_start", "map_to", "refine_family", "min_time", "min_jerk", "shortest",
           "certify_scaling", "infeasibility", "floor_infeasibility", "time_floor",
           "scaling_need", "scaling_needs", "sensitivities", "time_scale", "critical_values"]


CRITICAL_VALUES = 15
"""Limit constraints per knot span and joint without jerk limits: 6 travel, 5 velocity and 4
acceleration values at critical times (:func:`candidate_limits`); a problem has
``n_intervals × 8 × 15`` (720 in the paper's family)."""
JERK_VALUES = 3
"""Jerk constraints per knot span and joint of a problem with jerk limits: the jerk (a
quadratic) at the span's ends and its vertex."""


def critical_values(problem: DockingProblem) -> int:
    """Limit constraints per knot span and joint: :data:`CRITICAL_VALUES`, plus
    :data:`JERK_VALUES` with jerk limits."""
    return CRITICAL_VALUES + (JERK_VALUES if problem.jerk is not None else 0)


@dataclass(frozen=True)
class Solution:
    """One solved programme. ``x`` (n_var,) certified (kernel-feasible), ``F`` (2,) its
    (T, jerk), ``G`` (n_con,) its kernel columns; ``multipliers`` (n_intervals, 8,
    :func:`critical_values`) the Lagrange
    multipliers of the span constraints at the solver's point (objective scaled as in
    ``objective_scale``), ``scaled`` the time scaling applied to certify (1.0: none),
    ``cap_multiplier`` that of the time cap (jerk programme; ``d jerk*/d T = −scale · it``),
    ``iterations`` SLSQP's, ``success`` SLSQP's own verdict, ``message`` its message."""

    x: np.ndarray
    F: np.ndarray
    G: np.ndarray
    x_solver: np.ndarray
    multipliers: np.ndarray
    cap_multiplier: float
    objective_scale: float
    scaled: float
    iterations: int
    success: bool
    message: str


# -- the programmes' functions (jitted once per problem shape) ---------------------------------


def critical_times(problem: DockingProblem, x):
    """The critical times of :func:`candidate_limits` at x: per span and joint the travel's
    (6), the velocity's (5) and the acceleration's (4) candidate times ``τ ∈ [0, h]`` of
    :func:`dockjax.extrema.chain_extrema` (and, with jerk limits, the jerk's 3 of
    :func:`dockjax.extrema.jerk_times`), each with a flag that it is the span's end."""
    h, _, c, ref = spans(problem, x)
    polys = jax.lax.stop_gradient(robot.join_pairs([joint_series(rb, c, h, ref) for rb in problem.robots], axis=1))
    hh = jax.lax.stop_gradient(jnp.broadcast_to(h[:, None], polys.shape[:2]))
    (tt, _), (vt, _), at = extrema.chain_extrema(polys, hh)
    times = (tt, vt, at) if problem.jerk is None else (tt, vt, at, extrema.jerk_times(poly_derivative(polys, 3), hh))
    return tuple((t, t == hh[..., None]) for t in times)


def candidate_limits(problem: DockingProblem, x, limits=None, times=None):
    """The limit constraints at every critical time, x (n_var,) → (s spans, n_joints,
    :func:`critical_values`) (8 joints for the paper's two arms; a cabin on more supports:
    per pair of supports, :attr:`dockjax.DockingProblem.robots`, joined).

    Per span and joint: the travel at the span's ends and the roots of the velocity (6
    values), the velocity at the ends and the roots of the acceleration (5), the
    acceleration at the ends and the roots of the jerk (4) (and with jerk limits the jerk at
    the ends and its vertex, 3) (:func:`critical_times`), each
    as ``(q/L)² − (1 − r/L)|1 − r/L| ≤ 0`` with ``r`` the right arm's linearisation remainder (0
    elsewhere): smooth in x (the interior times carry no derivative, envelope theorem; a
    span's end moves with its interval), and ``max ≤ 0`` over the 15 is the kernel's
    ``"bound"`` feasibility up to the roots' certified widths. ``limits`` (8, kinds) replaces
    the problem's (for derivatives in them); ``times`` (:func:`critical_times`, default
    at x) holds the times fixed, so that derivatives need not trace the root searches."""
    L = problem.limits if limits is None else limits
    times = critical_times(problem, x) if times is None else times
    h, _, c, ref = spans(problem, x)
    if problem.supports is None:
        return _pair_limits(problem.robot, c, h, ref, L, times)
    parts = []
    for rb, rows in zip(problem.robots, robot.pair_rows(problem.n_supports)):
        pick = lambda a: jnp.take(a, rows, axis=1)  # noqa: E731  the pair's joints
        parts.append(_pair_limits(rb, c, h, ref, jnp.take(L, rows, axis=0),
                                  tuple((pick(t), pick(end)) for t, end in times)))
    return robot.join_pairs(parts, axis=1)


def _pair_limits(rb: robot.Robot, c, h, ref, L, times):
    """:func:`candidate_limits` of one two-arm robot: (s spans, 8 joints, critical values)."""
    polys = materialize(joint_series(rb, c, h, ref))  # (s, 8, 6)
    hh = jnp.broadcast_to(h[:, None], polys.shape[:2])
    vals = [poly_eval(poly_derivative(polys, k)[..., None, :] if k else polys[..., None, :],
                      jnp.where(end, hh[..., None], jax.lax.stop_gradient(t)))
            for k, (t, end) in enumerate(times)]
    rem = linearisation_remainders(rb, c, h, ref)  # (s, 3, kinds)
    extra = jnp.zeros(polys.shape[:2] + (rb.n_kinds,), polys.dtype).at[:, ATTITUDE_JOINTS].set(rem)
    out = []
    for k, v in enumerate(vals):
        room = 1.0 - extra[..., k, None] / L[:, k, None]
        # room·|room|, written so that its value and derivative are those of room² where
        # room >= 0: the constraint then keeps growing as the remainder r passes the limit
        out.append((v / L[:, k, None]) ** 2 - jnp.where(room >= 0.0, room ** 2, -(room ** 2)))
    return jnp.concatenate(out, -1)


def _jerk(problem, x):
    h, _, c, ref = spans(problem, x)
    return cabin_jerk(problem.robots, c, h, ref, nodes=problem.jerk_nodes, differentiable=True)


_jerk_value = stored_jit(_jerk)


def _x_of(problem, u):
    lo = problem.lower
    return lo + u * (problem.upper - lo)


def _objective(u, problem, scale, time_weight):
    """The programmes' objective ``(w T + (1 − w) jerk) / scale`` at unit-box coordinates u
    (w = ``time_weight``, 1 or 0)."""
    x = _x_of(problem, u)
    return (time_weight * jnp.sum(x[: problem.n_intervals]) + (1.0 - time_weight) * _jerk(problem, x)) / scale


@stored_jit
def _values(problem, u, scale, time_weight):
    """Objective ``(w T + (1 − w) jerk) / scale`` (w = ``time_weight``, 1 or 0: one compiled
    programme serves both programmes), its gradient, the constraints
    (n_intervals · 120,; 720 in the paper) and their Jacobian (·, d), in the unit-box
    coordinates u."""

    times = critical_times(problem, _x_of(problem, u))  # held: the root searches are not differentiated

    def g(u):
        return candidate_limits(problem, _x_of(problem, u), times=times).reshape(-1)

    fv, fg = jax.value_and_grad(_objective)(u, problem, scale, time_weight)
    # the Jacobian in forward mode, one tangent per coordinate, with the value computed once
    eye = jnp.eye(u.shape[0], dtype=u.dtype)
    gv, gj = jax.vmap(lambda d: jax.jvp(g, (u,), (d,)), out_axes=(None, 1))(eye)
    return fv, fg, gv, gj


@stored_jit
def _primal_values(problem, u, scale, time_weight):
    """:func:`_values` without the constraints' Jacobian: the objective, its gradient and the
    constraints. The Jacobian is most of :func:`_values`'s cost (in the paper's family
    0.35 of 0.63 ms a call, at 32 free control points about 20 times the rest), and SLSQP's
    line search asks for values alone; the objective and its gradient are bit for bit
    :func:`_values`'s, the constraints equal to rounding."""

    x = _x_of(problem, u)
    fv, fg = jax.value_and_grad(_objective)(u, problem, scale, time_weight)
    return fv, fg, candidate_limits(problem, x, times=critical_times(problem, x)).reshape(-1)


def _scores(problem, x):
    """The kernel's F (2,) and G (24,) of one x, every span through the root chain."""
    with jax.enable_x64(True):
        F, G = problem.evaluate(np.asarray(x, np.float64)[None], screen=False)
    return F[0], G[0]


def time_scale(problem: DockingProblem, x, s: float) -> np.ndarray:
    """``x`` with every interval multiplied by ``s`` (the same path, ``s`` times slower)."""
    x = np.array(x, np.float64)
    x[: problem.n_intervals] *= s
    return x


def scaling_needs(G, n_joints: int = config.N_JOINTS):
    """Per limit column, the exact time scaling ``s`` that brings it down to its limit:
    G (..., n_joints · kinds) → (..., n_joints, kinds) (8 joints: the paper's two arms). A kind of time-scaling power p
    (:data:`dockjax.robot.LIMIT_KINDS`: velocity 1, acceleration 2, jerk 3) scales by ``1/s^p``,
    so ``s`` is the p-th root of ``G + 1`` (the maximum over the limit); travel does not
    scale (0). NumPy in, NumPy out (float64); a JAX array (also traced) in, JAX out."""
    xp = jnp if isinstance(G, jax.Array) else np
    r = (G.reshape(G.shape[:-1] + (n_joints, -1)) if xp is jnp else by_kind(G, n_joints)) + 1.0
    root = {0: xp.zeros_like, 1: lambda v: v, 2: lambda v: xp.sqrt(xp.maximum(v, 0.0)), 3: xp.cbrt}
    return xp.stack([root[k.power](r[..., i]) for i, k in enumerate(robot.kinds_of(r.shape[-1]))], -1)


def scaling_need(G, n_joints: int = config.N_JOINTS):
    """The least time scaling ``s ≥ 1`` after which no rate column of G (...,
    n_joints · kinds) exceeds its limit (:func:`scaling_needs`). → (...,)."""
    xp = jnp if isinstance(G, jax.Array) else np
    return xp.maximum(1.0, scaling_needs(G, n_joints).max(axis=(-2, -1)))


class PlanError(RuntimeError):
    """No trajectory meets the limits (the command line's exit code 1). The message names
    the limit; so do the attributes, where one limit is to blame: ``joint`` (e.g.
    ``"d_L3"``), ``quantity`` (``"travel"``, ``"velocity"``, ``"acceleration"`` or ``"jerk"``),
    ``limit`` (its value) and ``unit``, and ``excess``, how far over the limit the best
    candidate found is (relative: 0.12 is 12 % over), or None where not measured."""

    def __init__(self, message: str, *, joint: str | None = None, quantity: str | None = None,
                 limit: float | None = None, unit: str | None = None, excess: float | None = None):
        super().__init__(message)
        self.joint, self.quantity, self.limit, self.unit, self.excess = joint, quantity, limit, unit, excess

    @classmethod
    def of_column(cls, problem: DockingProblem, j: int, k: int, message: str, excess: float | None = None):
        """The error for limit column (joint ``j``, quantity ``k``): ``message`` follows
        ``"<joint> <quantity> (<limit> <unit>)"``."""
        joint, kind = problem.joints[j], robot.LIMIT_KINDS[k]
        limit, unit = float(np.asarray(problem.limits)[j, k]), joint.unit + kind.suffix
        joint, kind = joint.name, kind.name
        return cls(message.replace("{limit}", f"{joint} {kind} ({limit:g} {unit})"), joint=joint, quantity=kind,
                   limit=limit, unit=unit, excess=excess)


MOVE_ROUNDING = 64.0
"""The joint moves of :func:`_joint_moves` are reduced by this many units of float64
rounding of the joint values (``eps · max(|q_start|, |q_goal|, 1)``): a bound on the
rounding of the inverse kinematics and the difference, so that the moves, and the time
floor built on them, never exceed the exact ones."""


def _joint_moves(problem: DockingProblem) -> np.ndarray:
    """(8,) |goal − start| of each joint (mm, °), in float64, less its rounding
    (:data:`MOVE_ROUNDING`; at least 0): never above the exact move."""
    with jax.enable_x64(True):
        ends = problem.arm_distance if problem.supports is None else problem.offsets
        q0, q1 = (np.asarray(inverse_kinematics(np.asarray(p, np.float64), ends))
                  for p in (problem.start, problem.goal))
    return moves_less_rounding(q0, q1)


def moves_less_rounding(q0, q1) -> np.ndarray:
    """|q1 − q0| of joint values (..., 8) in float64, less their rounding
    (:data:`MOVE_ROUNDING`; at least 0): never above the exact moves."""
    rounding = MOVE_ROUNDING * np.finfo(np.float64).eps * np.maximum(np.maximum(np.abs(q0), np.abs(q1)), 1.0)
    return np.maximum(np.abs(q1 - q0) - rounding, 0.0)


def _rate_limits(problem: DockingProblem) -> tuple[np.ndarray, np.ndarray]:
    """The velocity and acceleration limits (8,) each of the problem's limit table."""
    kind = [k.name for k in robot.LIMIT_KINDS]
    lim = np.asarray(problem.limits, np.float64)
    return lim[:, kind.index("velocity")], lim[:, kind.index("acceleration")]


def time_floor(problem: DockingProblem) -> np.ndarray:
    """(8,) s: per joint, the least time in which any motion from rest at its start value to
    rest at its goal value keeps |velocity| and |acceleration| within the problem's limits:
    the bang-bang profile (full acceleration, cruise at the velocity limit, full braking),
    ``d/v + v/a`` for a move ``d ≥ v²/a``, else the triangle ``2 √(d/a)``. Every trajectory
    the kernel certifies, of any family, takes at least the largest of them: a certified
    column bounds its quantity over the whole trajectory."""
    return _bang_bang(_joint_moves(problem), *_rate_limits(problem))


def _bang_bang(d, v, a) -> np.ndarray:
    """The least rest-to-rest time covering ``d`` within ``v`` and ``a`` (:func:`time_floor`)."""
    return np.where(d >= v * v / a, d / v + v / a, 2.0 * np.sqrt(d / a))


def floor_infeasibility(problem: DockingProblem) -> PlanError | None:
    """A :class:`PlanError` when some joint's :func:`time_floor` exceeds the longest T the
    interval bounds allow (no trajectory can meet its limits: no solve needed), naming that
    joint's velocity limit, or its acceleration limit when even an unlimited velocity would
    not do (``4 d / T² > a``); ``excess``: the least peak of that quantity over its limit,
    minus 1, at the longest T. None otherwise."""
    if problem.boundary is not None:  # the floor is for moves from rest to rest
        return None
    moves, (vs, accs) = _joint_moves(problem), _rate_limits(problem)
    floor = _bang_bang(moves, vs, accs)
    T = problem.n_intervals * problem.interval_bounds[1]
    j = int(np.argmax(floor))
    if floor[j] <= T * (1.0 + 1e-9):
        return None
    d, v, a = float(moves[j]), float(vs[j]), float(accs[j])
    kind = [k.name for k in robot.LIMIT_KINDS]
    if 4.0 * d > a * T * T:  # even the triangle at full acceleration is too slow
        k, excess = kind.index("acceleration"), 4.0 * d / (T * T) / a - 1.0
    else:  # the least cruise velocity that covers d in T with full acceleration
        k, excess = kind.index("velocity"), (a * T - math.sqrt(a * a * T * T - 4.0 * a * d)) / 2.0 / v - 1.0
    name, unit = problem.joints[j].name, problem.joints[j].unit
    return PlanError.of_column(
        problem, j, k, f"no trajectory meets the limit {{limit}}: {name} moves {d:.6g} {unit}, which takes at "
        f"least {floor[j]:.4g} s from rest to rest within {v:g} {unit}/s and {a:g} {unit}/s^2, beyond the longest "
        f"T = {T:g} s the interval bounds {problem.interval_bounds} allow", excess=float(excess))


def infeasibility(problem: DockingProblem) -> PlanError:
    """Why no trajectory of the decision box meets the limits: the limit that the straight
    line (the move's natural candidate) misses even slowed as far as the interval bounds
    allow, as a :class:`PlanError`; or, when that line meets every limit, that the solver
    failed."""
    x = straight_line(problem, [problem.n_intervals * problem.interval_bounds[1]])[0]
    F, G = problem.evaluate(x[None])
    G3 = by_kind(G[0], problem.n_joints)
    if G3[:, 0].max() > 0:
        j = int(np.argmax(G3[:, 0]))
        return PlanError.of_column(problem, j, 0, "no trajectory meets the limit {limit}: the straight line "
                                   f"already exceeds it by {100 * G3[j, 0]:.2f} %", excess=float(G3[j, 0]))
    if np.all(G[0] <= 0):
        return PlanError(f"the SQP found no certified trajectory, although the straight line at the longest "
                         f"T = {F[0, 0]:g} s meets every limit: the solver failed on this problem (try fewer "
                         f"control points or other interval bounds)")
    need = scaling_needs(G[0], problem.n_joints)
    j, k = np.unravel_index(np.argmax(need), need.shape)
    return PlanError.of_column(
        problem, int(j), int(k), f"no trajectory meets the limit {{limit}}: even the straight line would need "
        f"T >= {F[0, 0] * need[j, k]:.4g} s, beyond the longest T = {F[0, 0]:g} s the interval bounds "
        f"{problem.interval_bounds} allow", excess=float(G3[j, k]))


def certify_scaling(problem: DockingProblem, x, max_rounds: int = 8):
    """The least exact time scaling ``s ≥ 1`` found by the kernel that makes x feasible.

    Velocity columns scale by ``1/s``, accelerations by ``1/s²`` and jerks by ``1/s³`` exactly,
    travel not at all; s starts from the kernel's columns and grows by a hair until the kernel (never
    understated) says feasible. → ``(x_scaled, F, G, s)``, or ``None`` when a travel limit
    fails or the scaled intervals leave the decision box."""
    x = np.asarray(x, np.float64)
    F, G = _scores(problem, x)
    s = 1.0
    for _ in range(max_rounds):
        if np.all(G <= 0):
            return x, F, G, s
        if np.any(by_kind(G, problem.n_joints)[:, 0] > 0):
            return None
        step = float(scaling_need(G, problem.n_joints)) * (1.0 + 1e-9)
        s *= step
        x = time_scale(problem, x, step)
        if np.any(x[: problem.n_intervals] > problem.upper[: problem.n_intervals]):
            return None
        F, G = _scores(problem, x)
    return (x, F, G, s) if np.all(G <= 0) else None


RESTARTS = 3
"""Fresh SLSQP starts from the last point when a solve ends without converging, in families
of at most the paper's five free control points (:func:`family_restarts`)."""


def family_restarts(problem: DockingProblem) -> int:
    """Restarts of a solve in ``problem``'s family: :data:`RESTARTS` up to the paper's five
    free control points, none above. A restart renews SLSQP's curvature estimate; in larger
    families each costs tens of seconds of dense QP steps for a small gain (the shortest time
    of the default move with knot intervals in [0.05, 30] s and 32 points: 12.05774 s after
    three restarts in 90 s, against 12.06000 s, the paper family's start kept, in 13 s)."""
    return RESTARTS if problem.n_control <= config.N_FREE else 0


def _slsqp(problem, x0, kind, cap, scale, tol, max_iter, restarts=RESTARTS, room=0.0):
    """SLSQP in the unit box; ``room`` > 0 keeps the intervals that far (unit-box units) below
    their upper bounds, so that the certificate's time scaling fits inside the box."""
    lo, hi = np.asarray(problem.lower), np.asarray(problem.upper)
    width = hi - lo
    n = problem.n_intervals
    top = np.ones_like(width)
    top[:n] -= room
    u0 = np.clip((np.asarray(x0, np.float64) - lo) / width, 0.0, top)
    n_candidates = n * problem.n_joints * critical_values(problem)
    # values from one programme and the constraints' Jacobian from another: SLSQP's line
    # search asks for values alone, 1.5 to 9 times per iteration
    cache, jac_cache = {}, {}

    def values(u):
        key = u.tobytes()
        if key not in cache:
            cache.clear()
            with jax.enable_x64(True):
                out = _primal_values(problem, u, np.float64(scale), np.float64(kind == "time"))
            cache[key] = tuple(np.asarray(a, np.float64) for a in out)
        return cache[key]

    def jacobian(u):
        key = u.tobytes()
        if key not in jac_cache:
            jac_cache.clear()
            with jax.enable_x64(True):
                jac_cache[key] = np.asarray(_values(problem, u, np.float64(scale), np.float64(kind == "time"))[3],
                                            np.float64)
        return jac_cache[key]

    # a large programme keeps only its near-active limit constraints (the dense QP of each SQP
    # step costs in proportion to the constraints): those above -NEAR_ACTIVE at the start,
    # and, round by round, any other that comes within NEAR_ACTIVE / 2 of its limit
    keep = None if n_candidates <= DENSE_CONSTRAINTS else values(u0)[2] > -NEAR_ACTIVE
    nit = 0
    for _ in range(ACTIVE_ROUNDS if keep is not None else 1):
        if keep is None:
            cons = [{"type": "ineq", "fun": lambda u: -values(u)[2], "jac": lambda u: -jacobian(u)}]
        else:
            cons = [{"type": "ineq", "fun": lambda u, k=keep: -values(u)[2][k],
                     "jac": lambda u, k=keep: -jacobian(u)[k]}]
        if cap is not None:
            wh = width[:n]
            b = max(cap * (1.0 - 1e-12) - lo[:n].sum(), 0.0)  # a hair inside, never below the box
            a = np.zeros_like(u0)
            a[:n] = -wh
            cons.append({"type": "ineq", "fun": lambda u: b + a @ u, "jac": lambda u: a})
        last, last_res = None, None
        for _ in range(1 + restarts):  # a restart renews SLSQP's curvature estimate, while it helps
            res = minimize(lambda u: values(u)[0], u0, jac=lambda u: values(u)[1], method="SLSQP",
                           bounds=list(zip(np.zeros_like(top), top)), constraints=cons,
                           options={"maxiter": int(max_iter), "ftol": tol})
            nit += int(res.nit)
            if res.success:
                break
            u0 = np.clip(res.x, 0.0, top)
            now = (float(values(u0)[0]), float(max(np.max(values(u0)[2]), 0.0)))
            if last is not None and not _progress(last, now):
                res = last_res  # the restart did no better (it may have left the limits): keep the answer before it
                break
            last, last_res = now, res
        if keep is None:
            break
        u0 = np.clip(res.x, 0.0, top)
        g = values(u0)[2]
        if not np.any(~keep & (g > -0.5 * NEAR_ACTIVE)):
            break
        keep = keep | (g > -NEAR_ACTIVE)
    res.nit = nit
    m = np.asarray(getattr(res, "multipliers", np.zeros(0)), np.float64).ravel()
    n_kept = n_candidates if keep is None else int(keep.sum())
    mult = np.zeros(n_candidates)
    if m.size >= n_kept:
        if keep is None:
            mult = m[:n_candidates]
        else:
            mult[keep] = m[:n_kept]
    cap_mult = float(m[n_kept]) if cap is not None and m.size > n_kept else 0.0
    return lo + np.clip(res.x, 0.0, top) * width, res, (mult.reshape(n, problem.n_joints, -1), cap_mult)


RESTART_GAIN = 1e-9
"""A restart of SLSQP (:func:`_slsqp`) is followed by another only when it lowered the
objective by more than this fraction of itself, or the largest constraint violation by
more than this much (the constraints are dimensionless, ``(q/L)²`` against 1): restarts
that end where the last one did (a programme with no room left, e.g. the least jerk capped
at a shortest time whose answer has intervals at their upper bounds) are not repeated."""


def _progress(last, now) -> bool:
    """Whether ``now`` = (objective, violation) improves on ``last`` by :data:`RESTART_GAIN`."""
    return now[0] < last[0] - RESTART_GAIN * abs(last[0]) or now[1] < last[1] - RESTART_GAIN


DENSE_CONSTRAINTS = 720
"""Most limit constraints an SQP step takes all at once (the paper's family has 720); larger
programmes keep their near-active ones (:data:`NEAR_ACTIVE`)."""
NEAR_ACTIVE = 0.75
"""A limit constraint ``(q/L)² − (1 − r/L)²`` of a large programme is kept when above
``−NEAR_ACTIVE`` (the value above about half its limit); a solve is repeated, with the
constraints above that value added, while one left out comes within ``NEAR_ACTIVE / 2``, so a
programme's answer meets every constraint."""
ACTIVE_ROUNDS = 6
"""Most rounds of adding constraints to a large programme."""

INTERVAL_ROOM = 1e-6
"""Room (unit-box units) kept below the intervals' upper bounds when a solve is repeated because
the certificate's time scaling did not fit inside the box."""

SCALED_OK = 1e-7
"""A solver point whose certifying time scaling exceeds ``1 + SCALED_OK`` is solved again
from the scaled (feasible) trajectory."""


def _finish(problem, x, res, mult, scale):
    cert = certify_scaling(problem, x)
    if cert is None:
        return None
    xc, F, G, s = cert
    mult, cap_mult = mult
    return Solution(x=xc, F=np.asarray(F), G=np.asarray(G), x_solver=np.asarray(x), multipliers=mult,
                    cap_multiplier=cap_mult, objective_scale=float(scale),
                    scaled=float(s), iterations=int(res.nit), success=bool(res.success), message=str(res.message))


def _solve(problem, x0, kind, cap, scale, tol, max_iter, restarts):
    """SLSQP, certified; while the certificate had to slow the solver's point by more than
    :data:`SCALED_OK` (SLSQP stopped slightly outside the limits), up to ``restarts`` new
    solves from the slowed, feasible trajectory, as long as each improves on the last. The
    best certified answer is returned."""
    best, k = None, 0 if kind == "time" else 1
    room = 0.0
    for _ in range(1 + restarts):
        x, res, mult = _slsqp(problem, x0, kind, cap, scale, tol, max_iter, restarts, room)
        sol = _finish(problem, x, res, mult, scale)
        if sol is None and best is None and room == 0.0:
            # the certificate's time scaling (a hair, for the solver's tolerance) would push an
            # interval at its upper bound out of the box: solve again with room below it
            room = INTERVAL_ROOM
            x, res, mult = _slsqp(problem, x0, kind, cap, scale, tol, max_iter, restarts, room)
            sol = _finish(problem, x, res, mult, scale)
        if sol is None:
            break
        improved = best is None or sol.F[k] < best.F[k]
        if improved:
            best = sol
        if sol.scaled <= 1.0 + SCALED_OK or not improved:  # no gain: a new solve from the best repeats its own
            break
        x0 = sol.x
    return best


ACTIVE = 1e-6
"""A limit constraint above ``−ACTIVE``, or a box bound within ``ACTIVE`` (unit-box units),
counts as active in :func:`_multipliers_at`."""
STATIONARY = 0.1
"""Largest relative residual of :func:`_multipliers_at`'s fit for which the point counts as
stationary (its multipliers, and so its sensitivities, estimated). A start that is not a
KKT point leaves about all of ``|∇f|`` (the straight line slowed until feasible: 1.0). At a
degenerate optimum, where a limit binds along a plateau of its quantity, the candidate
constraints describe the constraint's subgradients only approximately: the wide preset's
shortest time (``d_L3`` velocity on a plateau) leaves 0.066, and the fitted sensitivity is
then within 1.3 % of the SQP's and of re-planning (−4.74 against −4.80 s per mm/s)."""


def _multipliers_at(problem, x, scale):
    """Lagrange multiplier estimates of the time programme at a feasible ``x`` that is not
    the solver's point: the non-negative least-squares fit of the objective's gradient by
    the active limit constraints' and box bounds' gradients (SciPy's ``lsq_linear``, BVLS),
    ``∇f + Σ λ_i ∇g_i − Σ ν_j e_j + Σ ν_k e_k ≈ 0``. → (n_intervals, 8, critical_values);
    None when the fit leaves more than :data:`STATIONARY` of ``|∇f|`` (x is not a KKT point:
    the sensitivities are unknown)."""
    lo, hi = np.asarray(problem.lower), np.asarray(problem.upper)
    u = (np.asarray(x, np.float64) - lo) / (hi - lo)
    with jax.enable_x64(True):
        _, fg, gv, gj = (np.asarray(a, np.float64) for a in _values(problem, u, np.float64(scale), np.float64(1.0)))
    active = gv > -ACTIVE
    eye = np.eye(u.size)
    A = np.concatenate([gj[active], -eye[u <= ACTIVE], eye[u >= 1.0 - ACTIVE]]).T  # bounds within a certified hair
    lam = lsq_linear(A, -fg, bounds=(0.0, np.inf), method="bvls").x
    if np.linalg.norm(A @ lam + fg) > STATIONARY * np.linalg.norm(fg):
        return None
    mult = np.zeros(gv.size)
    mult[active] = lam[: int(active.sum())]
    return mult.reshape(problem.n_intervals, problem.n_joints, -1)


def min_time(problem: DockingProblem, x0, *, tol: float = 1e-12, max_iter: int = 200,
             restarts: int | None = None) -> Solution | None:
    """The shortest ``T`` over trajectories meeting every limit, from ``x0`` (n_var,): SLSQP on
    ``min Σ h`` subject to the candidate constraints (:func:`candidate_limits`), in the unit
    box. ``x0`` is first made feasible by time scaling (:func:`certify_scaling`), so the
    search starts inside. ``restarts``: fresh solves after a stop without convergence or
    outside the limits (None: :func:`family_restarts`). The answer is never slower than the
    certified start: when the SQP ends slower, the start is returned, with multiplier
    estimates (:func:`_multipliers_at`). Returns None when no certified trajectory is found
    (travel infeasible from x0)."""
    start = certify_scaling(problem, x0)
    if start is not None:
        x0 = start[0]
    scale = float(np.sum(np.asarray(x0)[: problem.n_intervals]))
    restarts = family_restarts(problem) if restarts is None else restarts
    sol = _solve(problem, x0, "time", None, scale, tol, max_iter, restarts)
    if start is not None and (sol is None or sol.F[0] > start[1][0]):
        # the SQP ended slower than its own (certified) start: the start is the answer
        sol = kept_start(problem, start, multipliers=_multipliers_at(problem, start[0], scale), cap_multiplier=0.0,
                         objective_scale=scale, iterations=0 if sol is None else sol.iterations,
                         message="no certified trajectory faster than the start found; multipliers estimated at "
                         "the start")
    return sol


def kept_start(problem: DockingProblem, certified, *, multipliers=None, cap_multiplier: float = math.nan,
               objective_scale: float = 1.0, iterations: int = 0,
               message: str = "a certified start no solve improved on") -> Solution:
    """A certified start ``(x, F, G, s)`` (:func:`certify_scaling`) kept as the answer of a
    programme, as a :class:`Solution` (``success`` False); multipliers (n_intervals, 8,
    :func:`critical_values`) NaN, so its sensitivities unknown, unless given (not None)."""
    x, F, G, s = certified
    if multipliers is None:
        multipliers = np.full((problem.n_intervals, problem.n_joints, critical_values(problem)), np.nan)
    return Solution(x=np.asarray(x, np.float64), F=np.asarray(F), G=np.asarray(G), x_solver=np.asarray(x, np.float64),
                    multipliers=multipliers, cap_multiplier=cap_multiplier, objective_scale=objective_scale,
                    scaled=float(s), iterations=iterations, success=False, message=message)


def min_jerk(problem: DockingProblem, x0, cap: float, *, tol: float = 1e-12, max_iter: int = 200,
             restarts: int | None = None) -> Solution | None:
    """The least jerk (Eq. 25) with ``T ≤ cap`` and every limit, from ``x0`` (n_var,);
    ``restarts`` as in :func:`min_time`. The certified answer may be slower than ``cap`` by
    the certificate's time scaling (at most ``SCALED_OK`` unless restarts ran out)."""
    with jax.enable_x64(True):
        j0 = float(_jerk_value(problem, np.asarray(x0, np.float64)))
    scale = j0 if math.isfinite(j0) and j0 > 0 else 1.0
    restarts = family_restarts(problem) if restarts is None else restarts
    return _solve(problem, x0, "jerk", float(cap), scale, tol, max_iter, restarts)


SHORTEST_SLACK = 1e-4
"""Relative time above the shortest that :func:`shortest` accepts for a smoother trajectory
(the certificate's time scaling after the least-jerk solve at the shortest time: up to
5e-5 measured on moves whose joints, not the interval bounds, decide the time, for a jerk
up to fifteen times lower; 1e-4 of a 20 s move is 2 ms)."""


def shortest(problem: DockingProblem, x0, *, tol: float = 1e-12, max_iter: int = 200) -> Solution | None:
    """The shortest time (:func:`min_time`) and, among the trajectories that take it, the
    least jerk (:func:`min_jerk` at that cap, from the time optimum): the returned x, F and
    G are the latter's when it is smoother and at most :data:`SHORTEST_SLACK` slower; the
    multipliers, ``x_solver`` and so :func:`sensitivities` stay the time programme's
    (``d T_min / d limit``). Where the interval bounds decide the time (every interval at
    its lower bound) the shortest trajectories form a whole family, and the first
    answer of the time programme is rarely its smoothest: there the least jerk is solved
    from it and from the straight line of that T (:func:`least_jerk`); elsewhere from it,
    with :data:`RESTARTS` in the paper's family, so that the answer, the front's upper jerk
    end that Eq. 26 normalises by, hardly depends on where the time programme started; when
    nothing certified is found at T_min itself (the certificate's time scaling of an answer
    with intervals at their upper bounds leaves the box), at ``T_min (1 + SHORTEST_SLACK/2)``,
    the first cap of :func:`dockjax.bulk.plan_batch`'s front."""
    sol = min_time(problem, x0, tol=tol, max_iter=max_iter)
    if sol is None:
        return None
    n = problem.n_intervals
    if np.all(sol.x[:n] <= problem.lower[:n] * (1 + 1e-9)):  # the bounds decide T: the line takes it too
        smooth = least_jerk(problem, float(sol.F[0]), [sol.x], tol=tol, max_iter=max_iter)
    else:  # restarts by family: in the paper's a first solve often stops at several times the least jerk
        smooth = min_jerk(problem, sol.x, float(sol.F[0]), tol=tol, max_iter=max_iter)
        if smooth is None:  # nothing certified at T_min itself (no room to slow an answer): half the slack
            cap = float(sol.F[0]) * (1.0 + 0.5 * SHORTEST_SLACK)
            smooth = min_jerk(problem, sol.x, cap, tol=tol, max_iter=max_iter, restarts=0)
    if smooth is not None and smooth.F[1] < sol.F[1] and smooth.F[0] <= sol.F[0] * (1 + SHORTEST_SLACK):
        sol = dataclasses.replace(sol, x=smooth.x, F=smooth.F, G=smooth.G)
    return sol


@stored_jit
def _limit_gradient(problem, x, lam):
    """``∂/∂L Σ λ g(x; L)`` over the candidate constraints, at the problem's limits (8, kinds)."""
    times = critical_times(problem, x)
    return jax.grad(lambda L: jnp.sum(lam * candidate_limits(problem, x, L, times)))(problem.limits)


def sensitivities(problem: DockingProblem, sol: Solution) -> np.ndarray:
    """``d f* / d limit`` (8 joints, kinds) in the objective's units per limit unit,
    by the envelope theorem: ``Σ λ_i ∂g_i/∂L`` over the candidate constraints at the
    solver's point, λ the SLSQP multipliers of ``sol`` (unscaled). Zero for limits that do
    not bind; NaN when ``sol`` is a start kept by :func:`min_time` that is not a stationary
    point. For the time programme f* is T (s); for the jerk programme the jerk."""
    with jax.enable_x64(True):
        lam = np.asarray(sol.multipliers * sol.objective_scale, np.float64)
        return np.asarray(_limit_gradient(problem, np.asarray(sol.x_solver, np.float64), lam))


def straight_line(problem: DockingProblem, T) -> np.ndarray:
    """Decision vectors (len(T), n_var) of straight-line trajectories with equal intervals
    ``T/(n + 1)`` (the n interior control points evenly spaced from start to goal,
    conventions §3)."""
    T = np.atleast_1d(np.asarray(T, dtype=np.float64))
    s = problem.n_intervals
    h = np.repeat(T[:, None] / s, s, 1)
    if problem.reduced:
        return h
    i = np.arange(1, problem.n_control + 1)[:, None] / float(s)
    free = (problem.start + i * (problem.goal - problem.start)).ravel()
    return np.concatenate([h, np.tile(free, (T.size, 1))], 1)


def least_jerk(problem: DockingProblem, cap: float, starts, *, restarts: int = 0, tol: float = 1e-12,
               max_iter: int = 200) -> Solution | None:
    """The lowest-jerk :func:`min_jerk` solution at ``cap`` over the start points ``starts``
    (each (n_var,)) and the straight line with equal intervals (tried last; for a family of
    more than the paper's five control points only when no start is given: there the line
    is far from the optimum and its solve the dearest); then up to ``restarts`` fresh solves
    from the best solver point (a restart renews SLSQP's curvature estimate), while they
    lower the jerk."""
    best, tried = None, []
    line = [] if starts and problem.n_control > config.N_FREE else [straight_line(problem, [cap])[0]]
    for x0 in [*starts, *line]:
        x0 = np.asarray(x0, np.float64)
        # a start equal to an earlier one to rounding (the time programme's answer where it
        # is the straight line) ends where that one did
        if any(np.allclose(x0, t, rtol=1e-12, atol=0.0) for t in tried):
            continue
        tried.append(x0)
        s = min_jerk(problem, x0, cap, tol=tol, max_iter=max_iter)
        if s is not None and (best is None or s.F[1] < best.F[1]):
            best = s
    for _ in range(restarts if best is not None else 0):
        s = min_jerk(problem, best.x_solver, cap, tol=tol, max_iter=max_iter)
        if s is None or s.F[1] >= best.F[1] * (1 - 1e-12):
            break
        best = s
    return best


def least_jerk_front(problem: DockingProblem, shortest: Solution, caps, *, line: bool = True,
                     tol: float = 1e-12, max_iter: int = 200, restarts: int = RESTARTS,
                     on_cap: Callable[[], None] | None = None, seeds=None) -> list[Solution]:
    """The least-jerk trajectory at each time cap (sorted ascending, all above the shortest
    time), by continuation: :func:`min_jerk` from the previous cap's answer slowed to the
    new cap (feasible, by exact time scaling), and with ``line`` also from the straight
    line with equal intervals (:func:`least_jerk`), keeping the lower jerk. ``seeds``
    (len(caps), n_var), optional: cap k's solve starts from ``seeds[k]`` time-scaled to the
    cap instead of the previous cap's answer (a solved front of a nearby move converges in
    a few iterations), and falls back on the continuation when it finds nothing. Caps where
    no certified trajectory is found are skipped. ``max_iter`` and ``restarts`` bound each
    continuation solve (a coarse front for a choice need not converge fully). ``on_cap``
    is called after each cap (for a progress display)."""
    out, prev = [], shortest
    n = problem.n_intervals
    for k, cap in enumerate(np.sort(np.asarray(caps, np.float64))):
        start = time_scale(problem, prev.x, cap / prev.F[0])
        best = None
        if seeds is not None:
            seed = np.asarray(seeds[k], np.float64)
            best = min_jerk(problem, time_scale(problem, seed, cap / np.sum(seed[:n])), cap, tol=tol,
                            max_iter=max_iter, restarts=restarts)
        if best is None and line:
            best = least_jerk(problem, cap, [start], tol=tol, max_iter=max_iter)
        elif best is None:
            best = min_jerk(problem, start, cap, tol=tol, max_iter=max_iter, restarts=restarts)
            if best is None:
                best = least_jerk(problem, cap, [], tol=tol, max_iter=max_iter)
        if best is not None:
            out.append(best)
            prev = best
        if on_cap is not None:
            on_cap()
    return out


def refine_family(problem: DockingProblem, source: DockingProblem, x) -> np.ndarray | None:
    """The trajectory x (``source.n_var``,) of a family with fewer control points as a decision
    vector of ``problem``'s family (the same move, more control points): each interval cut
    into equal pieces (:func:`dockjax.bspline.split_counts`, none shorter than the lower
    interval bound where possible) and the knots inserted (:func:`dockjax.bspline.insert_knots`),
    so T, the jerk and every limit column are those of x up to rounding. None when
    ``problem`` has fewer control points than ``source``, either is reduced, or the pieces
    cannot all meet the interval bounds."""
    if problem.reduced or source.reduced or problem.n_control < source.n_control:
        return None
    x = np.asarray(x, np.float64)
    h = x[: source.n_intervals]
    counts = split_counts(h, problem.n_intervals, problem.interval_bounds[0])
    pieces = np.repeat(h / counts, counts)
    if pieces.min() < problem.interval_bounds[0] or pieces.max() > problem.interval_bounds[1]:
        return None
    u = np.concatenate([np.zeros(6), np.cumsum(h)[:-1], np.full(6, h.sum())])
    with jax.enable_x64(True):
        ctrl = np.asarray(control_points(source.start, source.goal,
                                                 x[source.n_intervals:].reshape(-1, config.N_POSE), h, source.boundary))
    t0 = np.concatenate([[0.0], np.cumsum(h)])
    new = np.concatenate([t0[k] + h[k] * np.arange(1, m) / m for k, m in enumerate(counts)])
    _, fine = insert_knots(u, ctrl, new)
    out = np.concatenate([pieces, fine[3:-3].ravel()])
    return np.clip(out, problem.lower, problem.upper)


def map_to(problem: DockingProblem, template: DockingProblem, X) -> np.ndarray:
    """Decision vectors X (n, n_var) of ``template`` carried over to ``problem`` (another
    start and goal, the same shape): the intervals are kept and each control point keeps
    its place relative to the straight line from start to goal, coordinate by
    coordinate, scaled by the ratio of the moves (shifted where the template's
    coordinate does not move). Clipped into ``problem``'s box; time scaling
    (:func:`certify_scaling`) then restores the limits."""
    X = np.array(X, np.float64, ndmin=2)
    if problem.reduced:
        return X.copy()
    s0, d0 = np.asarray(template.start), np.asarray(template.goal) - np.asarray(template.start)
    s1, d1 = np.asarray(problem.start), np.asarray(problem.goal) - np.asarray(problem.start)
    n = problem.n_intervals
    if template.n_control != problem.n_control:
        raise ValueError(f"map_to needs problems of one spline family: template has n_control="
                         f"{template.n_control}, problem {problem.n_control}")
    P = X[:, n:].reshape(len(X), problem.n_control, config.N_POSE)
    frac = (np.arange(1, problem.n_control + 1) / float(n))[:, None]
    moves = np.abs(d0) > 1e-12 * np.maximum(1.0, np.abs(s0))
    ratio = np.where(moves, d1 / np.where(moves, d0, 1.0), 1.0)
    Q = np.where(moves, s1 + (P - s0) * ratio, s1 + (P - s0) + frac * (d1 - d0))
    out = np.concatenate([X[:, :n], Q.reshape(len(X), -1)], 1)
    return np.clip(out, problem.lower, problem.upper)
