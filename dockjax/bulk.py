"""Certified plans of many moves in one compiled call (:func:`plan_batch`).

B moves of one robot (one limit table, one arm distance, one spline family) are planned by
one JAX program (:func:`_planned`): per move

1. the straight line at the shortest T the box allows, slowed until the kernel certifies
   it (exact time scaling, :func:`_certified`): the start;
2. the shortest-time programme by the batched SQP (:mod:`dockjax.sqp`) with the kernel's
   constraints at their critical times (:func:`dockjax.solve.candidate_limits`), from the
   start and from variants of it with the knot intervals redistributed (:func:`_time_starts`),
   each answer certified; T_min the shortest;
3. the least-jerk programme at the time caps of :func:`dockjax.plan.plan`'s front (T_min,
   then ``n_front`` caps geometrically spaced up to the longest T), each from the shortest-
   time trajectory slowed to its cap, all solved at once and each answer certified;
4. the front point of best weighted satisfaction (Eq. 26), or with a duration the least-jerk
   certified trajectory of exactly that duration (each programme's answer, and its start,
   time-scaled to it and certified there).

"Certified" is the kernel's rigorous maxima of every span through the root chain
(``screen=False``; the right arm treated as ``problem`` treats it): never below the true
maximum, so a move reported feasible meets every limit. A move no trajectory can make
within the interval bounds (:func:`dockjax.solve.floor_infeasibility`), or whose start
cannot be certified, is reported infeasible with the binding limit (:class:`dockjax.solve.PlanError`) and never solved.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from . import checks, config, robot, select, solve, sqp
from .kinematics import inverse_kinematics
from .objectives import jerk_nodes_for
from .problem import DockingProblem, _control_box, score_batch
from .solve import PlanError
from .store import stored_jit

__all__ = ["BatchPlan", "plan_batch", "stack_moves", "single", "PARAMS", "START_ITER", "FRONT_ITER",
           "DURATION_ITER"]

PARAMS = sqp.Params(max_iter=80)
"""SQP settings; ``max_iter``: most iterations of the shortest-time programme."""
START_ITER = 25
"""Most SQP iterations of the shortest-time programme from the other starts than the
straight line (:func:`_time_starts`; it converges in 10-20 from most)."""
FRONT_ITER = 60
"""Most SQP iterations of each least-jerk programme of the front (as many as
:data:`dockjax.plan.FRONT_ITER`)."""
DURATION_ITER = 150
"""Most SQP iterations of the least-jerk programmes of a duration (one plan, solved closer
to convergence than a front's caps)."""
DURATION_ROOM = 1e-5
"""The least-jerk programme of a duration T caps the time at ``T (1 − DURATION_ROOM)``; its
certified answer is then slowed to exactly T. The room takes up what the certificate's
time scaling adds to an answer that ends a hair outside a limit (about 1e-6 of T measured;
:func:`dockjax.plan.plan` lowers its cap and solves again instead); slowing by 1e-5 changes
the jerk by about 5e-5 of itself."""
ROUNDS = 8
"""Most rounds of exact time scaling in :func:`_certified`."""
TOP = 1.0 - 1e-6
"""The intervals' upper corner in the unit box of the shortest-time programme: a hair below
their upper bounds, so that the certificate's time scaling (a factor of about 1 + 1e-9) fits
inside the box."""
FRONT_TOP = 1.0 - 1e-3
"""The intervals' upper corner in the unit box of the least-jerk programmes: their answers,
stopped by :data:`FRONT_ITER` before convergence, may exceed a limit by about 1e-3, and the
certificate's time scaling needs that much room (the longest T of the front is then about
1e-3 × (hi − lo)/hi below the bounds' longest)."""


@dataclass(frozen=True)
class BatchPlan:
    """The plans of B moves (:func:`plan_batch`).

    ``x`` (B, n_var): the chosen certified trajectories (NaN where infeasible); ``T``,
    ``jerk`` (B,): their objectives; ``T_min`` (B,): the shortest certified time found;
    ``feasible`` (B,) bool; ``errors``: per move None or the :class:`PlanError` naming the
    limit that rules the move out; ``front`` (B, 1 + n_front, 2): (T, jerk) of the
    time-optimal trajectory and of each cap's least-jerk one (with a duration: of each
    programme's answer time-scaled to exactly the duration; NaN where nothing certified was
    found); ``chosen`` (B,): the index into ``front`` of the chosen point (−1
    with a duration or infeasible); ``iterations`` (B,): SQP iterations of the shortest-time
    programme, ``front_iterations`` (B, 1 + n_front) of the front's; ``problem``: the batched
    problem (a :class:`DockingProblem` whose leaves carry
    the batch axis, :func:`stack_moves`)."""

    x: np.ndarray
    T: np.ndarray
    jerk: np.ndarray
    T_min: np.ndarray
    feasible: np.ndarray
    errors: list
    front: np.ndarray
    chosen: np.ndarray
    iterations: np.ndarray
    front_iterations: np.ndarray
    problem: DockingProblem

    def __len__(self) -> int:
        return len(self.T)

    def __repr__(self) -> str:
        T = self.T[self.feasible]
        span = f", T from {T.min():.4g} to {T.max():.4g} s" if T.size else ""
        return f"BatchPlan({len(self)} moves, {int(self.feasible.sum())} feasible{span}, n_var={self.x.shape[1]})"

    def move(self, i: int) -> DockingProblem:
        """Move ``i`` as a single, validated :class:`DockingProblem`."""
        return single(self.problem, i)


def _moves(name: str, value, count: int | None) -> np.ndarray:
    arr = checks.real_array(name, value)
    if arr.ndim == 1:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != config.N_POSE or arr.shape[0] < 1:
        raise ValueError(f"{name} must be poses of shape (B, 6) with B >= 1, got shape {np.shape(value)}")
    if count is not None and arr.shape[0] != count:
        raise ValueError(f"{name} has {arr.shape[0]} poses but starts has {count}: give one goal per start")
    if not np.all(np.isfinite(arr)):
        i, j = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"{name}[{i}, {j}] must be finite, got {arr[i, j]}")
    return arr


def stack_moves(problem: DockingProblem, starts, goals) -> DockingProblem:
    """The moves ``starts`` → ``goals`` (each (B, 6), or one pose (6,)) of ``problem``'s robot,
    limits, interval bounds and family, as one :class:`DockingProblem` whose leaves carry a
    leading batch axis of B (vmap over it). Each move gets what ``DockingProblem`` gives a
    single move: its home (the midpoint of its start and goal joints, unless ``problem``'s
    home was given explicitly, then that one) and its control-point box. The jerk quadrature
    has the most nodes any move needs; the right arm keeps ``problem``'s treatment (each is
    certified: ``"bound"`` may overstate a column a little more for a move of larger
    attitude than ``problem``'s, never understate it). Checked vectorised (ValueError naming
    the move): a start equal to its goal, a joint move longer than its stroke, a start or
    goal outside the travel."""
    if not isinstance(problem, DockingProblem):
        raise ValueError(f"problem must be a DockingProblem, got {type(problem).__name__}")
    if problem.reduced:
        raise ValueError("plan_batch plans full decision vectors: give a problem with reduced=False")
    if problem.supports is not None:
        raise ValueError(f"plan_batch plans the paper's two arms; this cabin has {problem.n_supports} supports "
                         "(plan its moves one at a time with dockjax.plan or a Planner)")
    S = _moves("starts", starts, None)
    G = _moves("goals", goals, S.shape[0])
    B = S.shape[0]
    same = np.all(S == G, axis=1)
    if same.any():
        i = int(np.argmax(same))
        raise ValueError(f"move {i}: start and goal are the same pose {S[i].tolist()}: there is no move to plan")
    q0, q1 = _joints(problem, S), _joints(problem, G)
    limits = np.asarray(problem.limits, np.float64)
    explicit = _explicit_home(problem, _default_home(problem))
    home = np.broadcast_to(np.asarray(problem.home, np.float64), q0.shape) if explicit else 0.5 * (q0 + q1)
    move = np.abs(q1 - q0)
    bad = move > 2 * limits[:, 0]
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise ValueError(f"move {i}: start-to-goal move of joint {config.JOINT_NAMES[j]} is {move[i, j]:.6g} "
                         f"{config.JOINT_UNITS[j]}, longer than its stroke 2 x travel = {2 * limits[j, 0]:.6g}")
    for label, q in (("start", q0), ("goal", q1)):
        out = np.abs(q - home) > limits[:, 0] * (1 + 1e-12)
        if out.any():
            i, j = np.argwhere(out)[0]
            raise ValueError(f"move {i}: {label} value {q[i, j]:.6g} of joint {config.JOINT_NAMES[j]} is outside its "
                             f"travel {home[i, j]:.6g} ± {limits[j, 0]:.6g} about home")
    box_lo, box_hi = _control_box(S, G, float(problem.margin))  # (B, 6) each
    n, (lo, hi) = problem.n_intervals, problem.interval_bounds
    lower = np.concatenate([np.full((B, n), lo), np.tile(box_lo, problem.n_control)], 1)
    upper = np.concatenate([np.full((B, n), hi), np.tile(box_hi, problem.n_control)], 1)
    att = robot.POSE_ATTITUDE
    nodes = max(problem.jerk_nodes, jerk_nodes_for(float(np.max(box_hi[:, att] - box_lo[:, att]))))
    batched = jax.tree.map(lambda leaf: np.broadcast_to(np.asarray(leaf, np.float64), (B,) + np.shape(leaf)).copy(),
                           dataclasses.replace(problem, jerk_nodes=nodes))
    return dataclasses.replace(batched, start=S, goal=G, home=np.ascontiguousarray(home), box=(lower, upper))


def _joints(problem: DockingProblem, poses) -> np.ndarray:
    """The joints (B, 8) of poses (B, 6) for ``problem``'s arm distance, in float64."""
    with jax.enable_x64(True):
        ik = jax.vmap(inverse_kinematics, in_axes=(0, None))
        return np.asarray(ik(jnp.asarray(np.asarray(poses, np.float64)), float(problem.arm_distance)))


def _default_home(problem: DockingProblem) -> np.ndarray:
    q = _joints(problem, np.stack([problem.start, problem.goal]))
    return 0.5 * (q[0] + q[1])


def _explicit_home(problem: DockingProblem, default: np.ndarray) -> bool:
    """Whether ``problem``'s home differs from the one ``DockingProblem`` gives by default
    (then the user chose it, and every move keeps it)."""
    return not np.array_equal(np.asarray(problem.home, np.float64), default)


def single(batched: DockingProblem, i: int) -> DockingProblem:
    """Move ``i`` of a batched problem (:func:`stack_moves`) as a validated single problem."""
    leaf = lambda a: np.asarray(a)[i]  # noqa: E731
    kw = {f.name: getattr(batched, f.name) for f in dataclasses.fields(batched) if f.init and f.name != "box"}
    kw.update({k: leaf(kw[k]) for k in ("start", "goal", "home", "travel", "velocity", "acceleration")})
    kw.update(arm_distance=float(leaf(kw["arm_distance"])), margin=float(leaf(kw["margin"])),
              interval_bounds=tuple(float(leaf(v)) for v in kw["interval_bounds"]),
              jerk=None if kw["jerk"] is None else leaf(kw["jerk"]))
    return DockingProblem(**kw)


# -- the compiled program, per move (vmapped) ------------------------------------------------


def _score(p: DockingProblem, x):
    F, G = score_batch(p, x[None], screen=False)
    return F[0], G[0]


def _certified(p: DockingProblem, x):
    """x slowed by exact time scaling until the kernel certifies it (as
    :func:`dockjax.solve.certify_scaling`, at most :data:`ROUNDS` rounds). → ``(x, F, G, ok)``;
    ``ok`` false when a travel column fails, the intervals leave the box, or the rounds run out."""
    n = p.n_intervals
    kinds = p.n_kinds

    def failed(x, G):
        travel = G.reshape(config.N_JOINTS, kinds)[:, 0]
        return jnp.any(travel > 0) | jnp.any(x[:n] > p.upper[:n]) | ~jnp.all(jnp.isfinite(G))

    # k counts the kernel's evaluations: the first scores x as it is, each later one after a
    # scaling (one call of the kernel in the loop's body, so one copy in the program)
    def cond(c):
        x, F, G, k = c
        return (k == 0) | ((k <= ROUNDS) & jnp.any(G > 0) & ~failed(x, G))

    def body(c):
        x, F, G, k = c
        x = x.at[:n].multiply(jnp.where(k == 0, 1.0, solve.scaling_need(G) * (1.0 + 1e-9)))
        return (x, *_score(p, x), k + 1)

    start = (x, jnp.zeros(2, x.dtype), jnp.zeros(p.n_con, x.dtype), jnp.zeros((), jnp.int32))
    x, F, G, _ = jax.lax.while_loop(cond, body, start)
    return x, F, G, jnp.all(G <= 0) & ~failed(x, G)


def _line(p: DockingProblem, T):
    """The straight line of duration T with equal intervals (:func:`dockjax.solve.straight_line`)."""
    s = p.n_intervals
    i = jnp.arange(1, p.n_control + 1)[:, None] / float(s)
    free = (p.start + i * (p.goal - p.start)).ravel()
    return jnp.concatenate([jnp.full(s, T / s), free])


def _unit(p: DockingProblem, x, top_interval):
    top = jnp.ones(p.n_var, x.dtype).at[: p.n_intervals].set(top_interval)
    return jnp.clip((x - p.lower) / (p.upper - p.lower), 0.0, top), top


def _lane(p: DockingProblem, x0, time_weight, cap, limit, target):
    """One programme from x0 by at most ``limit`` SQP iterations (0: x0 as it is), its answer
    certified (:func:`_certified`): shortest time (``time_weight`` 1, ``cap`` unused) or least
    jerk (0) with ``T <= cap``. ``target`` > 0 (s): the answer and x0 are first time-scaled
    to exactly that T, and only a certified trajectory of exactly that T is ``ok``. →
    ``(x, F, G, ok, iterations)`` of the better certified of the answer and x0."""
    n = p.n_intervals
    u0, top = _unit(p, x0, jnp.where(time_weight > 0, TOP, FRONT_TOP))
    scale = jnp.where(time_weight > 0, jnp.sum(x0[:n]), jnp.maximum(solve._jerk(p, x0), 1e-12))
    width = p.upper - p.lower
    a = jnp.zeros_like(u0).at[:n].set(width[:n] * (1.0 - time_weight))
    b = jnp.where(time_weight > 0, 1.0, cap * (1.0 - 1e-12) - jnp.sum(p.lower[:n]))
    m = n * config.N_JOINTS * solve.critical_values(p)

    def objective(u):
        return solve._objective(u, p, scale, time_weight)

    def primal(u):
        return objective(u), solve.candidate_limits(p, solve._x_of(p, u)).reshape(-1)

    def values(u):
        return solve._values.fun(p, u, scale, time_weight)

    state = sqp.init(u0, m, sqp.positive_definite(jax.hessian(objective)(u0)))
    state = jax.lax.while_loop(lambda st: (st.k < limit) & ~st.done,
                               lambda st: sqp.step(st, values, primal, a, b, top, PARAMS), state)
    # the answer and the start (each first slowed or sped up to exactly ``target`` when one
    # is given), each certified; the better one certified (an answer the certificate cannot
    # slow into the box, e.g. one left a little infeasible by the iteration limit with
    # intervals at their upper bounds, falls back on the start)
    xs = jnp.stack([solve._x_of(p, state.u), x0])
    timed = target > 0
    factor = jnp.where(timed, target / jnp.sum(xs[:, :n], axis=1), 1.0)
    xs = xs.at[:, :n].set(jnp.minimum(xs[:, :n] * factor[:, None], p.upper[:n]))
    x, F, G, ok = jax.vmap(lambda x: _certified(p, x))(xs)
    # of a duration: no interval cut at its bound, none slowed further by the certificate
    ok = ok & (~timed | (jnp.abs(jnp.sum(x[:, :n], axis=1) - target) <= 1e-9 * target))
    f = jnp.where(time_weight > 0, F[:, 0], F[:, 1])
    i = jnp.where(ok[0] & (~ok[1] | (f[0] <= f[1])), 0, 1)
    return x[i], F[i], G[i], ok[i], state.k


def _time_starts(p: DockingProblem, x, lanes: int):
    """``lanes`` starts of the shortest-time programme: x (the certified straight line), then
    x with the same duration and control points but its knot intervals redistributed, more
    time at the ends of the move (odd lanes) or in its middle (even lanes), more so lane by
    lane (clipped to the interval bounds). The time programme's answer depends on its start
    (from the line alone the SQP may stall well above the shortest time). A vmapped loop
    computes every lane at each iteration anyway; the other starts cost the iterations
    they take beyond the line's (at most :data:`START_ITER`): in a batch of 100 moves,
    about a third of the plans per second."""
    n = p.n_intervals
    k = jnp.arange(lanes)[:, None]
    c = (n - 1) / 2.0
    shape = ((jnp.arange(n) - c) / max(c, 1.0)) ** 2  # 0 in the middle, 1 at the ends
    a = jnp.where(k % 2 == 1, 2.0, -0.5) * k / max(lanes - 1, 1)
    w = 1.0 + a * shape
    h = jnp.sum(x[:n]) * w / jnp.sum(w, axis=1, keepdims=True)
    h = jnp.where(k == 0, x[:n], jnp.clip(h, p.lower[:n], p.upper[:n]))
    return jnp.broadcast_to(x, (lanes, x.shape[0])).at[:, :n].set(h)


def _better(new, old):
    """The certified one of two ``(x, F, G, ok)`` with the shorter time."""
    take = new[3] & (~old[3] | (new[1][0] < old[1][0]))
    return jax.tree.map(lambda a, b: jnp.where(take, a, b), new, old)


def _planned(P: DockingProblem, weights, duration, n_front: int):
    """Every move's plan (module docstring): ``P`` the batched problem (leaves (B, ...)),
    ``duration`` (B,) (> 0: the least-jerk plan of that duration instead of a choice by
    ``weights``; one program serves both). → a dict of per-move x, F, ok, T_min, front
    (n_front + 1, 2), front_ok, chosen, iterations, cap_iterations (each with a leading B).

    The three steps run as one ``lax.scan`` over stages of one body (one compiled SQP and one
    certificate, however many stages): each stage solves ``n_front + 1`` programmes of every
    move at once, B × (n_front + 1) lanes in one vmapped call of :func:`_lane`; the first
    stage certifies the straight line (no SQP), the second solves the shortest-time
    programme in every lane, from the certified line and its variants
    (:func:`_time_starts`), and keeps the shortest certified answer, the third the
    least-jerk programme at every cap of the front, or at the duration from the
    shortest-time trajectory slowed to it (first lane) and from the straight line of that
    duration (the others). The scan is outside every vmap, and the lanes of all moves are
    one vmapped axis: the loops inside are batched once, not once per level (tracing and
    compiling the program takes that much less)."""
    B = duration.shape[0]
    lanes = n_front + 1
    first = jnp.arange(lanes) == 0
    repeat = jax.tree.map(lambda leaf: jnp.repeat(leaf, lanes, axis=0), P)  # each move's problem per lane
    lines = jax.vmap(lambda p: _line(p, p.n_intervals * p.interval_bounds[0]))(P)

    def caps_of(p, T_min, d):
        longest = p.n_intervals * p.interval_bounds[1]
        ratio = jnp.where(longest > T_min * (1 + 1e-9), longest / T_min, 1.0)
        caps = T_min * ratio ** (jnp.arange(lanes) / n_front)
        # the first cap: the least jerk among the shortest, within half the slack shortest() allows
        # of a duration: a hair below it, so that the certificate's slowing stays within it
        return jnp.where(d > 0, d * (1.0 - DURATION_ROOM), caps.at[0].multiply(1.0 + 0.5 * solve.SHORTEST_SLACK))

    def starts(p, line, short_x, T_min, d, s):
        """One move's lanes at stage s: starts (lanes, n_var), caps, iteration limits, targets."""
        n = p.n_intervals
        timed = d > 0
        caps = caps_of(p, T_min, d)
        scaled = jnp.broadcast_to(short_x, (lanes, short_x.shape[0]))
        scaled = scaled.at[:, :n].set(jnp.minimum(scaled[:, :n] * (caps / T_min)[:, None], p.upper[:n]))
        scaled = jnp.where((timed & ~first)[:, None], _line(p, d), scaled)
        x0 = jnp.where(s == 0, line, jnp.where(s == 1, _time_starts(p, short_x, lanes), scaled))
        limit = jnp.where(s == 0, 0, jnp.where(s == 1, jnp.where(first, PARAMS.max_iter, START_ITER),
                                               jnp.where(timed, DURATION_ITER, FRONT_ITER)))
        target = jnp.where((s == 2) & timed, d, 0.0)
        return x0, caps, limit, jnp.broadcast_to(target, (lanes,))

    def merge(out, short, s):
        """One move's best so far after stage s, and the lane of its shortest certified time."""
        lane0 = jax.tree.map(lambda a: a[0], out)
        # the shortest certified time of the lanes (stage 1 solves the time programme in
        # every lane, each from its own start)
        k = jnp.argmin(jnp.where(out[3], out[1][:, 0], jnp.inf))
        best = jax.tree.map(lambda a: a[k], out)
        new = jax.tree.map(lambda a, b, c: jnp.where(s == 0, a, jnp.where(s == 1, b, c)),
                           lane0, _better(best, short), short)
        return new, k

    def stage(short, s):
        x0, caps, limit, target = jax.vmap(starts, in_axes=(0, 0, 0, 0, 0, None))(P, lines, short[0], short[1][:, 0],
                                                                                duration, s)
        flat = lambda a: a.reshape((B * lanes,) + a.shape[2:])  # noqa: E731
        out = jax.vmap(_lane, in_axes=(0, 0, None, 0, 0, 0))(repeat, flat(x0), jnp.where(s == 2, 0.0, 1.0),
                                                             flat(caps), flat(limit), flat(target))
        out = jax.tree.map(lambda a: a.reshape((B, lanes) + a.shape[1:]), out)
        new, k = jax.vmap(merge, in_axes=(0, 0, None))(out[:4], short, s)
        return new, (*out, k)

    n_con = P.n_con
    empty = (lines, jnp.zeros((B, 2), lines.dtype), jnp.zeros((B, n_con), lines.dtype), jnp.zeros(B, bool))
    short, outs = jax.lax.scan(stage, empty, jnp.arange(3))
    return jax.vmap(_finish, in_axes=(0, 1, 1, 1, 1, 1, 1, None, 0))(
        short, *outs[:4], outs[4], outs[5], weights, duration)


def _finish(short, X, F, G, ok, iterations, k, weights, d):
    """One move's answer from its stages' lanes (``X`` (3, lanes, n_var), ...; ``k`` (3,):
    the lane of each stage's shortest certified time): by weights, the time-optimal
    trajectory is the front's first point, smoothed where the first cap found less jerk,
    and the choice of Eq. 26; of a duration, every lane's answer (or start) time-scaled to
    exactly the duration and certified there, the first lane's start being the
    shortest-time trajectory slowed to it: the least jerk of those."""
    sols = (X[2], F[2], G[2], ok[2])
    iters, cap_iters = iterations[1, k[1]], iterations[2]
    T_min = short[1][0]
    smooth = jax.tree.map(lambda a: a[0], sols)
    keep = smooth[3] & (smooth[1][1] < short[1][1]) & (smooth[1][0] <= T_min * (1 + solve.SHORTEST_SLACK))
    head = jax.tree.map(lambda a, b: jnp.where(keep, a, b), smooth, short)
    Xf, Ff, _, okf = (jnp.concatenate([h[None], v[1:]]) for h, v in zip(head, sols))
    j = _choose(Ff, weights, okf)
    okd = sols[3] & short[3]
    i = jnp.argmin(jnp.where(okd, sols[1][:, 1], jnp.inf))
    timed = d > 0
    pick = lambda a, b: jnp.where(timed, a, b)  # noqa: E731
    return dict(x=pick(sols[0][i], Xf[j]), F=pick(sols[1][i], Ff[j]), ok=pick(okd[i], okf[j]), T_min=T_min,
                front=pick(sols[1], Ff), front_ok=pick(okd, okf), chosen=pick(-1, j), iterations=iters,
                cap_iterations=cap_iters)


def _choose(F, weights, valid):
    """Eq. 26 on the valid rows of F (k, 2) (:func:`dockjax.select.satisfaction`; ties: the
    lowest index)."""
    big = jnp.finfo(F.dtype).max
    fmin = jnp.min(jnp.where(valid[:, None], F, big), axis=0)
    fmax = jnp.max(jnp.where(valid[:, None], F, -big), axis=0)
    span = jnp.where(fmax - fmin > 0, fmax - fmin, 1.0)
    delta = ((fmax - F) / span) @ weights / F.shape[1]
    return jnp.argmax(jnp.where(valid, delta, -jnp.inf))


@stored_jit(static_argnums=(0,))
def _plan_moves(n_front: int, p: DockingProblem, weights, duration):
    """:func:`_planned` of the batched ``p`` (``duration`` (B,), 0: by weights)."""
    return _planned(p, weights, duration, n_front)


def _bucket(b: int) -> int:
    """Moves per compiled call: 1, 2, 4, ... up to 64, then multiples of 64."""
    return 1 << max(0, (b - 1).bit_length()) if b <= 64 else -(-b // 64) * 64


def _floor(problem: DockingProblem, S, G) -> np.ndarray:
    """(B,) whether some joint's least rest-to-rest time exceeds the longest T
    (:func:`dockjax.solve.time_floor`, vectorised with the same rounding allowance)."""
    d = solve.moves_less_rounding(_joints(problem, S), _joints(problem, G))
    v, a = solve._rate_limits(problem)
    floor = solve._bang_bang(d, v, a).max(axis=1)
    return floor > problem.n_intervals * problem.interval_bounds[1] * (1.0 + 1e-9)


def plan_batch(problem: DockingProblem | None = None, starts=None, goals=None, *, weights=(1.0, 1.0),
               duration: float | None = None, n_front: int = config.PLAN_FRONT,
               chunk: int = 64) -> BatchPlan:
    """Certified plans of the B moves ``starts[i] → goals[i]`` ((B, 6) each) of ``problem``'s
    robot, limits, interval bounds and spline family (module docstring).

    ``weights`` (w_T, w_jerk): the front point of best weighted satisfaction (Eq. 26) among
    the time-optimal trajectory and the least-jerk ones at ``n_front`` caps up to the longest
    T, as :func:`dockjax.plan.plan` chooses; ``duration`` (s): instead, the least-jerk
    certified trajectory of exactly that duration (moves whose shortest time exceeds it are
    infeasible, their error naming that time). The moves go through the compiled program in
    chunks of at most ``chunk`` (padded to a power of two up to 64, then to a multiple of
    64: one compiled program per size). Raises ValueError on bad input, before any solve;
    infeasible moves are reported in the result, not raised."""
    problem = problem or DockingProblem()
    w = select.check_weights(weights, 2)
    checks.integer("n_front", n_front, 2, 200)
    checks.integer("chunk", chunk, 1)
    P = stack_moves(problem, problem.start if starts is None else starts, problem.goal if goals is None else goals)
    d = None
    if duration is not None:
        d = checks.number("duration", duration, 0.0, open_lo=True)
        longest = problem.n_intervals * problem.interval_bounds[1]
        if d > longest:
            raise ValueError(f"duration {d:g} s is longer than the longest T = {longest:g} s the interval bounds "
                             f"{problem.interval_bounds} allow ({problem.n_intervals} intervals); widen the bounds")
    B = P.start.shape[0]
    blocked = _floor(problem, P.start, P.goal)
    todo = np.flatnonzero(~blocked)
    out = {"x": np.full((B, problem.n_var), np.nan), "F": np.full((B, 2), np.nan), "ok": np.zeros(B, bool),
           "T_min": np.full(B, np.nan), "front": np.full((B, 1 + n_front, 2), np.nan),
           "front_ok": np.zeros((B, 1 + n_front), bool), "chosen": np.full(B, -1),
           "iterations": np.zeros(B, int), "cap_iterations": np.zeros((B, n_front + 1), int)}
    with jax.enable_x64(True):
        for lo in range(0, len(todo), chunk):
            idx = todo[lo:lo + chunk]
            size = _bucket(len(idx))
            pad = np.concatenate([idx, np.repeat(idx[:1], size - len(idx))])
            Pc = jax.tree.map(lambda leaf: np.asarray(leaf)[pad], P)
            res = _plan_moves(n_front, Pc, jnp.asarray(w), jnp.full(size, 0.0 if d is None else d))
            for k, v in res.items():
                out[k][idx] = np.asarray(v)[: len(idx)]
    F = out["F"]
    ok = out["ok"].copy()
    front = np.where(out["front_ok"][..., None], out["front"], np.nan)
    errors: list = [None] * B
    for i in np.flatnonzero(~ok):
        errors[i] = _why(problem, P, i, d, out["T_min"][i])
    x = np.where(ok[:, None], out["x"], np.nan)
    return BatchPlan(x=x, T=np.where(ok, F[:, 0], np.nan), jerk=np.where(ok, F[:, 1], np.nan),
                     T_min=np.where(np.isfinite(out["T_min"]) & out["front_ok"][:, 0], out["T_min"], np.nan),
                     feasible=ok, errors=errors, front=front, chosen=np.where(ok, out["chosen"], -1),
                     iterations=out["iterations"], front_iterations=out["cap_iterations"], problem=P)


def _why(problem: DockingProblem, P: DockingProblem, i: int, d: float | None, T_min: float) -> PlanError:
    """The :class:`PlanError` of infeasible move ``i`` (host-side, on the single problem)."""
    one = single(P, i)
    floor = solve.floor_infeasibility(one)
    if floor is not None:
        return floor
    if d is not None and math.isfinite(T_min):
        if d < T_min:
            return PlanError(f"move {i}: no trajectory takes {d:g} s: the shortest feasible time found is "
                             f"{T_min:.6g} s")
        return PlanError(f"move {i}: the least-jerk solve at T = {d:g} s found no certified trajectory of that "
                         "duration")
    err = solve.infeasibility(one)
    return PlanError(f"move {i}: {err}", joint=err.joint, quantity=err.quantity, limit=err.limit, unit=err.unit,
                     excess=err.excess)
