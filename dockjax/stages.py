"""Staged moves: a start, via poses and a goal, planned as one certified trajectory.

Docking runs in stages (approach, axis alignment, insertion), with slower envelopes near
contact and stops for measurement. A staged move is a start, a goal and :class:`Via` poses
between them; stage k runs from point k to point k + 1 (the start, the vias in order, the
goal), each one spline of the problem's family (its ``n_control``, interval bounds, arm
distance and home). At a via with ``stop = True`` the motion comes to rest and stays there
``dwell`` seconds; with ``stop = False`` it passes through the via's pose with continuous
velocity and acceleration, the via's pose velocity and acceleration being decision
variables (the two control points next to the via follow from them, conventions §2). A
via's ``limits`` apply to the stage that leaves it: ``{"scale": s}`` multiplies the robot's
velocity, acceleration and jerk limits by ``s`` (travel is geometry and stays), other keys
replace the limits they name (as a limits file).

:func:`plan_staged` solves every stage together with SciPy's SLSQP on the kernel's limit
constraints at their critical times (:func:`dockjax.solve.candidate_limits`, one compiled
programme for the whole move): the shortest total time, then the least jerk at ``n_front``
caps of the total time, and Eq. 26 chooses among them. The jerk of a staged move is Eq. 25
over its whole motion, ``Σ_j sqrt(Σ_k ∫ q_j'''² dt / Σ_k T_k)`` (dwells left out); its time
is ``Σ_k T_k`` plus the dwells. Each stage is then certified by the kernel's rigorous maxima
and by sampling, like a plan (a whole move slowed by exact time scaling when the solver
stopped a hair outside a limit: the intervals times ``s``, the vias' velocities over ``s``
and accelerations over ``s²``, the same path).
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import minimize

from . import checks, config, plots, robot, select
from .decoding import spans
from .io import atomic_write_text, check_input_file, write_set
from .objectives import mean_square_jerk, safe_sqrt
from .plan import BINDING, _certify, _shortest, load_limits
from .problem import BOUNDARY_FIELDS, DockingProblem
from .solve import RESTART_GAIN, PlanError, candidate_limits, critical_times, scaling_need
from .trajectory import Trajectory, csv_text
from .version import __version__

__all__ = ["Via", "Stage", "StagedPlan", "check_vias", "load_move", "load_move_problem", "stage_problems",
           "plan_staged", "write_staged", "STAGED_FILES", "MAX_MOVE_FILE"]

MAX_MOVE_FILE = 2**20
"""Largest move file read (bytes)."""

RATE_KINDS = ("velocity", "acceleration", "jerk")
"""The limits a via's ``scale`` multiplies."""


@dataclass(frozen=True)
class Via:
    """A pose the move goes through: ``pose`` (6,) mm and degrees; ``stop``: at rest there
    (else passed through with continuous velocity and acceleration); ``dwell`` (s, stops
    only); ``limits``: of the stage that leaves it (``{"scale": s}`` or limit keys)."""

    pose: Any
    stop: bool = True
    dwell: float = 0.0
    limits: dict | None = None


def check_vias(vias) -> tuple[Via, ...]:
    """The vias (each a :class:`Via` or a dict of its fields, as a move file's ``[[via]]``
    tables), checked: ValueError naming the via and what is wrong."""
    if vias is None:
        return ()
    if isinstance(vias, (Via, dict)) or not hasattr(vias, "__iter__"):
        raise ValueError(f"via must be a list of vias, got {type(vias).__name__}")
    out = []
    for k, v in enumerate(vias, 1):
        where = f"via {k}"
        if isinstance(v, dict):
            unknown = set(v) - {f.name for f in dataclasses.fields(Via)}
            if unknown:
                raise ValueError(f"{where}: unknown key(s) {', '.join(sorted(unknown))} (known: pose, stop, dwell, "
                                 "limits)")
            if "pose" not in v:
                raise ValueError(f"{where}: no pose")
            v = Via(**v)
        elif not isinstance(v, Via):
            raise ValueError(f"{where} must be a Via or a table, got {type(v).__name__}")
        pose = checks.vector(f"{where}: pose", v.pose, (6,))
        stop = checks.boolean(f"{where}: stop", v.stop)
        dwell = checks.number(f"{where}: dwell", v.dwell, 0.0)
        if dwell > 0 and not stop:
            raise ValueError(f"{where}: a dwell of {dwell:g} s needs stop = true (a via passed through has no dwell)")
        limits = None
        if v.limits is not None:
            if not isinstance(v.limits, dict):
                raise ValueError(f"{where}: limits must be a table, got {type(v.limits).__name__}")
            limits = dict(v.limits)
            if "scale" in limits:
                limits["scale"] = checks.number(f"{where}: limits.scale", limits["scale"], 0.0, open_lo=True)
            rest = {k: x for k, x in limits.items() if k != "scale"}
            if "home" in rest:
                raise ValueError(f"{where}: limits cannot move home (one home for the whole move)")
            if rest:
                limits.update(robot.check_limit_table(rest, f"{where}: limits"))
        out.append(Via(pose=pose, stop=stop, dwell=dwell, limits=limits))
    return tuple(out)


def load_move(path: str | Path) -> dict:
    """A move file (TOML): ``start``, ``goal`` (6 numbers each) and ``[[via]]`` tables
    (``pose``, optional ``stop`` (default true), ``dwell``, ``[via.limits]``). → the keyword
    arguments ``start``, ``goal`` and ``via`` (checked: ValueError naming the file and what
    is wrong)."""
    p = check_input_file(path, "move file", MAX_MOVE_FILE)
    try:
        data = tomllib.loads(p.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"move file {p} is not valid TOML: {exc}") from None
    unknown = set(data) - {"start", "goal", "via"}
    if unknown:
        raise ValueError(f"move file {p}: unknown key(s) {', '.join(sorted(unknown))} (known: start, goal, via)")
    try:
        out = {k: checks.vector(k, data[k], (6,)) for k in ("start", "goal") if k in data}
        out["via"] = check_vias(data.get("via", []))
    except ValueError as exc:
        raise ValueError(f"move file {p}: {exc}") from None
    return out


def _stage_limits(problem: DockingProblem, via: Via | None) -> dict:
    """The limit keywords of the stage leaving ``via`` (None: the start)."""
    kw = {q.name: np.asarray(problem.limits[:, k]) for k, q in enumerate(problem.kinds)}
    if via is None or via.limits is None:
        return kw
    scale = via.limits.get("scale", 1.0)
    for name in RATE_KINDS:
        if name in kw:
            kw[name] = kw[name] * scale
    kw.update({k: np.asarray(v, np.float64) for k, v in via.limits.items() if k != "scale"})
    return kw


def stage_problems(problem: DockingProblem, vias) -> list[DockingProblem]:
    """One problem per stage, at rest at both ends: the points in order (``problem``'s start,
    the vias, its goal), ``problem``'s home, arm distance, interval bounds and family, each
    stage with the limits of the via it leaves. ValueError naming the stage when a stage
    cannot be planned (a point outside the travel about home, or a stage that does not
    move)."""
    vias = check_vias(vias)
    if problem.supports is not None:
        raise ValueError(f"staged moves are for the paper's two arms; this cabin has {problem.n_supports} supports")
    points = [np.asarray(problem.start)] + [v.pose for v in vias] + [np.asarray(problem.goal)]
    base = {k: v for k, v in problem.identity().items()
            if k not in ("start", "goal", "travel", "velocity", "acceleration", "jerk", *BOUNDARY_FIELDS)}
    out = []
    for k in range(len(points) - 1):
        via = vias[k - 1] if k else None
        try:
            p = DockingProblem(**base, start=points[k], goal=points[k + 1], **_stage_limits(problem, via))
        except ValueError as exc:
            raise ValueError(f"stage {k + 1}: {exc}") from None
        if np.array_equal(points[k], points[k + 1]):
            raise ValueError(f"stage {k + 1}: its start and end are the same pose {points[k].tolist()}")
        out.append(p)
    return out


# -- the programme over every stage --------------------------------------------------------------

def _with_states(problems, through):
    """Stage problems whose moving ends (next to a via passed through) carry state leaves."""
    zero = np.zeros(6)
    out = []
    for k, p in enumerate(problems):
        moving = (k > 0 and through[k - 1]) or (k < len(problems) - 1 and through[k])
        out.append(dataclasses.replace(p, **dict.fromkeys(BOUNDARY_FIELDS, zero)) if moving else p)
    return out


def _via_states(z, through, offset: int, scales) -> dict:
    """``{via index: (velocity (6,), acceleration (6,))}`` of each via passed through, read
    from the programme's vector z from ``offset`` on, in units of ``scales`` (2, 6)."""
    states = {}
    for i, t in enumerate(through):
        if t:
            states[i] = (z[offset:offset + 6] * scales[0], z[offset + 6:offset + 12] * scales[1])
            offset += 12
    return states


def _end_states(k: int, states: dict) -> dict:
    """Stage k's boundary fields set by the vias passed through at its ends (:func:`_via_states`)."""
    kw = {}
    if k - 1 in states:
        kw.update(start_velocity=states[k - 1][0], start_acceleration=states[k - 1][1])
    if k in states:
        kw.update(goal_velocity=states[k][0], goal_acceleration=states[k][1])
    return kw


def _split(problems, z, scales, layout):
    """``[(stage problem with its ends' states, x_k)]`` of the programme's vector z: each
    stage's unit-box coordinates, then (v, a) of each via passed through, in units of
    ``scales`` (2, 6)."""
    n_var, through = layout
    states = _via_states(z, through, len(problems) * n_var, scales)
    out = []
    for k, p in enumerate(problems):
        u = z[k * n_var:(k + 1) * n_var]
        kw = _end_states(k, states)
        out.append((dataclasses.replace(p, **kw) if kw else p, p.lower + u * (p.upper - p.lower)))
    return out


def _objective(z, problems, scales, scale, time_weight, layout):
    """``(w T + (1 − w) jerk) / scale`` of the whole motion (dwells aside)."""
    T, squares = 0.0, 0.0
    for p, x in _split(problems, z, scales, layout):
        h, _, c, ref = spans(p, x)
        Tk = jnp.sum(h)
        T = T + Tk
        squares = squares + Tk * mean_square_jerk(p.robot, c, h, ref, p.jerk_nodes)
    return (time_weight * T + (1.0 - time_weight) * jnp.sum(safe_sqrt(squares / T))) / scale


@partial(jax.jit, static_argnames=("layout", "with_jacobian"))
def _values(problems, z, scales, scale, time_weight, layout, with_jacobian):
    """Objective, its gradient, every stage's limit constraints at their critical times
    (held) and, ``with_jacobian``, their Jacobian in z."""
    parts = _split(problems, z, scales, layout)
    times = [critical_times(p, x) for p, x in parts]

    def g(z):
        return jnp.concatenate([candidate_limits(p, x, times=t).reshape(-1)
                                for (p, x), t in zip(_split(problems, z, scales, layout), times)])

    fv, fg = jax.value_and_grad(_objective)(z, problems, scales, scale, time_weight, layout)
    if not with_jacobian:
        return fv, fg, g(z)
    eye = jnp.eye(z.shape[0], dtype=z.dtype)
    gv, gj = jax.vmap(lambda d: jax.jvp(g, (z,), (d,)), out_axes=(None, 1))(eye)
    return fv, fg, gv, gj


@dataclass
class _Programme:
    """The staged move as one vector programme (host side)."""

    problems: list
    vias: tuple
    through: tuple
    scales: np.ndarray

    @property
    def layout(self):
        return (self.problems[0].n_var, self.through)

    @property
    def n_z(self) -> int:
        return len(self.problems) * self.problems[0].n_var + 12 * sum(self.through)

    def z_of(self, xs, states) -> np.ndarray:
        """The vector of stage decision vectors ``xs`` and via states ``{i: (v, a)}``."""
        us = [(np.asarray(x) - p.lower) / (p.upper - p.lower) for p, x in zip(self.problems, xs)]
        vs = [np.concatenate([states[i][0] / self.scales[0], states[i][1] / self.scales[1]])
              for i, t in enumerate(self.through) if t]
        return np.concatenate(us + vs)

    def parts(self, z) -> tuple[list, dict]:
        """``(xs, states)`` of z (NumPy)."""
        n = self.problems[0].n_var
        xs = [p.lower + z[k * n:(k + 1) * n] * (p.upper - p.lower) for k, p in enumerate(self.problems)]
        return xs, _via_states(z, self.through, len(self.problems) * n, self.scales)

    def stage(self, k: int, states: dict) -> DockingProblem:
        """Stage k's problem with its ends' states."""
        p = self.problems[k]
        kw = _end_states(k, states)
        if not kw:
            return p
        rest = np.zeros(6)
        full = {f: kw.get(f, rest) for f in BOUNDARY_FIELDS}
        return dataclasses.replace(p, **full)

    def bounds(self, reach: float = 1.0) -> list:
        """SLSQP's bounds: the stages' unit boxes, and the vias' states within ``reach`` of
        their scales."""
        n = len(self.problems) * self.problems[0].n_var
        return [(0.0, 1.0)] * n + [(-reach, reach)] * (12 * sum(self.through))

    def time_row(self) -> tuple[np.ndarray, float]:
        """``(a, c)``: the total motion time is ``a @ z + c``."""
        a, c = np.zeros(self.n_z), 0.0
        n = self.problems[0].n_var
        for k, p in enumerate(self.problems):
            m = p.n_intervals
            a[k * n:k * n + m] = (p.upper - p.lower)[:m]
            c += float(np.sum(p.lower[:m]))
        return a, c

    def values(self, z, time_weight: float, scale: float, with_jacobian: bool):
        with jax.enable_x64(True):
            out = _values(_with_states(self.problems, self.through), jnp.asarray(z), jnp.asarray(self.scales),
                          np.float64(scale), np.float64(time_weight), self.layout, with_jacobian)
        return tuple(np.asarray(a, np.float64) for a in out)


def _programme(problem: DockingProblem, vias) -> _Programme:
    problems = stage_problems(problem, vias)
    through = tuple(not v.stop for v in vias)
    lim = np.max([p.limits for p in problems], axis=0)  # (8, kinds): the largest over the stages
    linear = np.array([u == "mm" for u in config.JOINT_UNITS])
    scales = np.array([[lim[linear, k].max()] * 3 + [lim[~linear, k].max()] * 3 for k in (1, 2)])
    return _Programme(problems, vias, through, scales)


def _solve(prog: _Programme, z0, time_weight: float, cap: float | None, *, reach: float = 1.0, max_iter: int = 300,
           tol: float = 1e-12):
    """SLSQP on the programme from z0: the total time (``time_weight`` 1) or the jerk under
    the total-time ``cap``, the vias' states within ``reach`` (:meth:`_Programme.bounds`). → z."""
    scale = 1.0 if time_weight else max(float(prog.values(z0, 0.0, 1.0, False)[0]), 1e-12)
    cache = {}

    def vals(z, jac=False):
        key = (z.tobytes(), jac)
        if key not in cache:
            if len(cache) > 4:
                cache.clear()
            cache[key] = prog.values(z, time_weight, scale, jac)
        return cache[key]

    cons = [{"type": "ineq", "fun": lambda z: -vals(z)[2], "jac": lambda z: -vals(z, True)[3]}]
    if cap is not None:
        a, c = prog.time_row()
        cons.append({"type": "ineq", "fun": lambda z: cap * (1 - 1e-12) - c - a @ z, "jac": lambda z: -a})
    bounds = prog.bounds(reach)
    z = np.clip(z0, [b[0] for b in bounds], [b[1] for b in bounds])
    best = None
    for _ in range(3):  # a restart renews SLSQP's curvature estimate, while it does better
        res = minimize(lambda z: vals(z)[0], z, jac=lambda z: vals(z)[1], method="SLSQP", bounds=bounds,
                       constraints=cons, options={"maxiter": max_iter, "ftol": tol})
        z = res.x
        rank = (max(float(vals(z)[2].max()), FEASIBLE), float(vals(z)[0]))
        better = best is None or rank[0] < best[0][0] - RESTART_GAIN or (
            rank[0] <= best[0][0] and rank[1] < best[0][1] - RESTART_GAIN * abs(best[0][1]))
        if better:
            best = (rank, z)
        if res.success or not better:
            break
    return best[1]


FEASIBLE = 1e-6
"""Constraint values up to this count as met when restarts of :func:`_solve` are compared
(the certificate's time scaling absorbs them)."""


def _scores(prog: _Programme, z):
    """Per stage ``(problem with its states, x, F, G)`` by the kernel (every span through the
    root chain)."""
    xs, states = prog.parts(z)
    out = []
    for k, x in enumerate(xs):
        p = prog.stage(k, states)
        with jax.enable_x64(True):
            F, G = p.evaluate(np.asarray(x)[None], screen=False)
        out.append((p, x, np.asarray(F[0]), np.asarray(G[0])))
    return out


def _certified(prog: _Programme, z, max_rounds: int = 8):
    """z slowed by the least exact time scaling the kernel certifies (every stage's
    intervals × s, the vias' velocities / s and accelerations / s²): ``(z, scores, s)``, or
    None when a travel limit fails or the intervals leave their box."""
    total = 1.0
    for _ in range(max_rounds):
        scores = _scores(prog, z)
        G = np.stack([s[3] for s in scores])
        if np.all(G <= 0):
            return z, scores, total
        if np.any(robot.by_kind(G.max(0))[:, 0] > 0):
            return None
        s = float(np.max(scaling_need(G))) * (1.0 + 1e-9)
        total *= s
        xs, states = prog.parts(z)
        xs = [np.concatenate([x[:p.n_intervals] * s, x[p.n_intervals:]]) for p, x in zip(prog.problems, xs)]
        if any(np.any(x[:p.n_intervals] > p.upper[:p.n_intervals]) for p, x in zip(prog.problems, xs)):
            return None
        z = prog.z_of(xs, {i: (v / s, a / s**2) for i, (v, a) in states.items()})
    return None


SCALED_OK = 1e-7
"""A solver point whose certifying time scaling exceeds ``1 + SCALED_OK`` is solved again
from the scaled (feasible) point (:func:`_solved`)."""


REACHES = (0.1, 1.0)
"""The vias' states are freed in steps (fractions of their scales, :meth:`_Programme.bounds`):
from a start at rest there, a first programme whose via may only move slowly keeps SLSQP's
first steps near the start; each step starts from the last one's answer."""


def _solved(prog: _Programme, z0, time_weight: float, cap: float | None, restarts: int = 4):
    """:func:`_solve` from z0 (with the vias' states freed step by step, :data:`REACHES`,
    when z0 is at rest at every via), certified (:func:`_certified`); while the certificate
    had to slow the solver's point by more than :data:`SCALED_OK` (SLSQP ended outside a
    limit), solved again from the slowed, feasible point. The best certified answer by the
    programme's objective (the total time, or the jerk), or None."""
    best, z = None, z0
    reaches = list(REACHES) if any(prog.through) and not np.any(z0[prog.n_z - 12 * sum(prog.through):]) else [1.0]
    for _ in range(len(reaches) + restarts):
        reach = reaches.pop(0) if reaches else 1.0
        got = _certified(prog, _solve(prog, z, time_weight, cap, reach=reach))
        if got is None:
            if reaches:
                continue
            break
        key = _time(got[1]) if time_weight else _jerk_of(got[1])
        if best is None or key < best[0]:
            best = (key, got)
        if got[2] <= 1.0 + SCALED_OK and not reaches:
            break
        z = got[0]
    return None if best is None else best[1]


def _time(scores) -> float:
    return float(sum(s[2][0] for s in scores))


@dataclass
class Stage:
    """One stage of a :class:`StagedPlan`: its ``problem`` (with its ends' states),
    ``trajectory``, ``x``, ``T``, ``G`` (the kernel's columns), ``start_s`` (its start on
    the move's clock), ``samples`` (certified) and ``binding``: the limits within 0.1 % of
    their value (name, value, unit)."""

    problem: DockingProblem
    trajectory: Trajectory
    x: np.ndarray
    T: float
    G: np.ndarray
    start_s: float
    samples: dict
    binding: list = field(default_factory=list)


@dataclass
class StagedPlan:
    """A certified staged move: ``stages``, the ``vias``, total ``T`` (s, dwells included),
    ``jerk`` (Eq. 25 over the whole motion), ``front`` (T, jerk) of the solved caps,
    ``weights``, ``rate``."""

    stages: list
    vias: tuple
    T: float
    jerk: float
    front: np.ndarray
    weights: tuple
    rate: float

    def __repr__(self) -> str:
        parts = ", ".join(f"{s.T:.3f} s" for s in self.stages)
        return f"StagedPlan(T={self.T:.4f} s, jerk={self.jerk:.5g}, {len(self.stages)} stages: {parts})"

    def _kept(self) -> list[int]:
        """Per stage, the first of its samples on the move's clock: 1 where its first sample
        repeats the previous stage's last (no dwell between them), else 0."""
        out, t_last = [], None
        for s in self.stages:
            out.append(int(t_last is not None and s.start_s <= t_last + 1e-12))
            t_last = s.start_s + s.samples["t"][-1]
        return out

    def sample(self) -> dict[str, np.ndarray]:
        """The whole move sampled (each stage's samples on the move's clock, a dwell as its
        two ends): ``t``, ``pose``, ``position``, ``velocity``, ``acceleration``, ``jerk``."""
        kept = self._kept()
        out = {"t": np.concatenate([s.start_s + s.samples["t"][k:] for s, k in zip(self.stages, kept)])}
        for key in ("pose", *robot.DERIVATIVES):
            out[key] = np.concatenate([s.samples[key][k:] for s, k in zip(self.stages, kept)])
        return out

    def sample_limits(self) -> np.ndarray:
        """The limit table of each sample of :meth:`sample` (its stage's): (m, 8, kinds)."""
        rows = [np.broadcast_to(np.asarray(s.problem.limits), (len(s.samples["t"][k:]),) + np.shape(s.problem.limits))
                for s, k in zip(self.stages, self._kept())]
        return np.concatenate(rows)


def _jerk_of(scores) -> float:
    squares, T = np.zeros(config.N_JOINTS), 0.0
    for p, x, F, _ in scores:
        with jax.enable_x64(True):
            h, _, c, ref = spans(p, jnp.asarray(x))
            squares += float(F[0]) * np.asarray(mean_square_jerk(p.robot, c, h, ref, p.jerk_nodes))
        T += float(F[0])
    return float(np.sum(np.sqrt(squares / T)))


def plan_staged(problem: DockingProblem | None = None, via=(), *, weights=(1.0, 1.0), rate: float = config.RATE,
                n_front: int = config.PLAN_FRONT) -> StagedPlan:
    """A certified staged move: ``problem``'s start to its goal through ``via`` (a list of
    :class:`Via` or dicts; see the module docstring), chosen by ``weights`` (w_T, w_jerk) of
    Eq. 26 over the front of the shortest total time and the least jerk at ``n_front``
    caps up to the longest total time (a zero jerk weight: the shortest time alone).
    ValueError on bad input (naming the via or stage), :class:`PlanError` when no plan is
    found."""
    problem = problem or DockingProblem()
    w = select.check_weights(weights, 2)
    rate = checks.rate(rate)
    n_front = checks.integer("n_front", n_front, 2, 200)
    prog = _programme(problem, check_vias(via))
    dwell = float(sum(v.dwell for v in prog.vias))
    # a feasible start: each stage's own shortest time, at rest at every via
    xs = []
    for k, p in enumerate(prog.problems):
        try:
            xs.append(_shortest(p).x)
        except PlanError as exc:
            raise PlanError(f"stage {k + 1}: {exc}", joint=exc.joint, quantity=exc.quantity, limit=exc.limit,
                            unit=exc.unit, excess=exc.excess) from None
    rest = {i: (np.zeros(6), np.zeros(6)) for i, t in enumerate(prog.through) if t}
    z0 = prog.z_of(xs, rest)
    first = _solved(prog, z0, 1.0, None)
    start = _certified(prog, z0)  # the stages' own shortest times, at rest at every via
    if first is None or (start is not None and _time(start[1]) < _time(first[1])):
        first = start
    if first is None:
        raise PlanError("no staged plan certifies: every solver answer fails a limit")
    sols = [first]
    if w[1] != 0:
        a, c0 = prog.time_row()
        t_max = c0 + float(np.sum(a))
        prev = first[0]
        for cap in np.linspace(_time(first[1]), t_max, n_front + 1)[1:]:
            got = _solved(prog, prev, 0.0, float(cap))
            if got is not None:
                sols.append(got)
                prev = got[0]
    F = np.array([[_time(sc) + dwell, _jerk_of(sc)] for _, sc, _ in sols])
    pick = 0 if w[1] == 0 else select.choose(F, w)
    _, scores, _ = sols[pick]
    stages, t0 = [], 0.0
    for k, (p, x, Fk, G) in enumerate(scores):
        samples = _certify(p, x, rate)
        names = p.column_names
        binding = [{"limit": names[i], "value": float(np.asarray(p.limits).reshape(-1)[i]),
                    "unit": config.unit(i // p.n_kinds, p.kinds[i % p.n_kinds].order)}
                   for i in np.flatnonzero(G > -BINDING)]
        stages.append(Stage(p, p.decode(x), np.asarray(x), float(Fk[0]), G, t0, samples, binding))
        t0 += float(Fk[0]) + (prog.vias[k].dwell if k < len(prog.vias) else 0.0)
    return StagedPlan(stages, prog.vias, float(F[pick, 0]), float(F[pick, 1]), F, tuple(w), rate)


def load_move_problem(path: str | Path, limits: str | Path | None = None, **kw) -> tuple[DockingProblem, tuple]:
    """``(problem, vias)`` of a move file (:func:`load_move`), with an optional limits file
    and other :class:`DockingProblem` keywords (the file's start and goal replace those
    given here)."""
    move = load_move(path)
    extra = load_limits(limits) if limits is not None else {}
    kw = {**kw, **extra, **{k: move[k] for k in ("start", "goal") if k in move}}
    return DockingProblem(**kw), move["via"]


STAGED_FILES = ("trajectory.csv", "summary.json", "trajectory.png")
"""Every file :func:`write_staged` writes."""


def _summary(sp: StagedPlan) -> dict:
    return {
        "dockjax_version": __version__, "T_s": sp.T, "jerk": sp.jerk, "front": sp.front.tolist(),
        "weights": list(sp.weights), "rate": sp.rate,
        "stages": [{"start_s": s.start_s, "T_s": s.T, "start": np.asarray(s.problem.start).tolist(),
                    "goal": np.asarray(s.problem.goal).tolist(),
                    "start_state": None if s.problem.boundary is None else
                    [np.asarray(b).tolist() for b in s.problem.boundary[:2]],
                    "goal_state": None if s.problem.boundary is None else
                    [np.asarray(b).tolist() for b in s.problem.boundary[2:]],
                    "dwell_after_s": sp.vias[k].dwell if k < len(sp.vias) else 0.0,
                    "limits": {q.name: np.asarray(s.problem.limits[:, i]).tolist()
                               for i, q in enumerate(s.problem.kinds)},
                    "binding": s.binding, "x": s.x.tolist()} for k, s in enumerate(sp.stages)],
    }


def write_staged(sp: StagedPlan, out: str | Path) -> list[Path]:
    """Write a staged plan into ``out`` as one set (:func:`dockjax.io.write_set`):
    trajectory.csv (the whole move on its clock, columns as a plan's), summary.json (each
    stage's start time, duration, ends, states, limits, binding limits and x) and
    trajectory.png (every joint against its stage's limits)."""
    def write(stage: Path) -> list[Path]:
        s = sp.sample()
        files = [atomic_write_text(stage / "trajectory.csv", csv_text(s))]
        files.append(atomic_write_text(stage / "summary.json", json.dumps(_summary(sp), indent=2) + "\n"))
        files.append(plots.plot_joints(s, sp.sample_limits(), stage / "trajectory.png", home=sp.stages[0].problem.home,
                                       title=f"staged move, T = {sp.T:.2f} s, jerk = {sp.jerk:.4g}"))
        return files

    return write_set(out, write, owned=STAGED_FILES)

