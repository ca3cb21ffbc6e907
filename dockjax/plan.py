"""One certified, explained docking trajectory a controller can run (``dockjax plan``).

:func:`plan` finds the problem's shortest feasible time and its least-jerk front by
sequential quadratic programming (:mod:`dockjax.solve`; or runs an optimiser), chooses a
point by the weighted satisfaction of Eq. 26 (conventions §8), and certifies it before
anything is written: the trajectory sampled at the servo rate must respect every limit at
every sample, and the kernel's per-span maxima (conventions §6: rigorous upper bounds, never
understated, in every right-arm treatment) must too; otherwise :class:`PlanError` names the
limit that cannot be met. :func:`explain` says which limits bind and what each is worth;
:class:`Planner` replans new poses of one problem in milliseconds; :func:`plan_batch`
(:mod:`dockjax.bulk`) plans many moves in one compiled call.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy
from tqdm import tqdm

from . import checks, config, plots, robot, select, solve, store
from .algorithms import ALGORITHMS
from .bulk import BatchPlan, plan_batch
from .export import EXPORTS, axis_tables, joint_trajectory, to_json, to_yaml
from .io import DamagedFileError, atomic_savez, atomic_write_text, check_input_file, load_npz, write_set
from .metrics import nondominated_points
from .optimize import optimize
from .problem import DockingProblem
from .refine import refine as polish
from .solve import PlanError
from .trajectory import Trajectory, bucket_durations
from .version import __version__

__all__ = ["PlanError", "Plan", "Planner", "plan", "plan_batch", "BatchPlan", "explain", "explain_text",
           "check_options", "check_move", "load_limits", "write_plan", "check_duration", "METHODS"]


@dataclass
class Plan:
    """A certified trajectory. ``samples``: t (m,), pose (m, 6), position/velocity/
    acceleration/jerk (m, 8) at ``rate`` Hz with a last sample at exactly T."""

    problem: DockingProblem
    trajectory: Trajectory
    x: np.ndarray
    T: float
    jerk: float
    front: np.ndarray
    samples: dict
    rate: float
    weights: tuple
    settings: dict = field(default_factory=dict)
    explanation: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        binding = ", ".join(b["limit"] for b in self.explanation.get("binding", [])) or "none"
        return (f"Plan(T={self.T:.4f} s, jerk={self.jerk:.5g}, {len(self.samples['t'])} samples at {self.rate:g} Hz, "
                f"weights={tuple(float(w) for w in self.weights)}, binding limits: {binding})")

    def margins(self) -> dict:
        """Per joint: max |velocity|, |acceleration|, travel about home (from the samples),
        and certified margins to the limits (from the kernel's G with every span through
        the root chain, never understated: exact to rounding for the joints linear in the
        pose, within the right-arm treatment's tolerance for the others)."""
        s, lim = self.samples, self.problem.limits
        G = robot.by_kind(self.problem.evaluate(self.x[None], screen=False)[1][0], self.problem.n_joints)
        peaks = _sampled_peaks(self.problem, s)
        out = {}
        for j, joint in enumerate(self.problem.joints):
            name = joint.name
            exact = (G[j] + 1.0) * lim[j]
            row = {"unit": joint.unit}
            for k, kind in enumerate(self.problem.kinds):
                label = "max_travel_from_home" if k == 0 else f"max_abs_{kind.name}"
                row[label] = float(peaks[j, k])
            for k, kind in enumerate(self.problem.kinds):
                row[f"{kind.name}_limit"] = float(lim[j, k])
            for k, kind in enumerate(self.problem.kinds):
                row[f"{kind.name}_margin"] = float(lim[j, k] - exact[k])
            out[name] = row
        return out


MAX_LIMITS_FILE = 2**20
"""Largest limits file read (bytes)."""


def load_limits(path: str | Path) -> dict:
    """Read limit overrides from a TOML or JSON file: keys ``travel``, ``velocity``,
    ``acceleration``, ``jerk`` (4 or 8 numbers) and ``home`` (8 numbers). Unknown keys are refused."""
    path = check_input_file(path, "limits file", MAX_LIMITS_FILE)
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark is not part of the text
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"limits file {path} cannot be read: {getattr(exc, 'strerror', None) or exc}") from None
    suffix = path.suffix.lower()
    parsers = {".toml": (("TOML", tomllib.loads),), ".json": (("JSON", json.loads),)}.get(
        suffix, (("JSON", json.loads), ("TOML", tomllib.loads)))
    data, errors = None, []
    for kind, parse in parsers:
        try:
            data = parse(text)
            break
        except Exception as exc:  # noqa: BLE001 - any parse error is bad input
            errors.append(f"{kind}: {exc}")
    if data is None:
        kinds = " nor ".join(k for k, _ in parsers)
        raise ValueError(f"limits file {path} is not valid {kinds if len(parsers) == 1 else 'neither ' + kinds} "
                         f"({'; '.join(errors)})")
    return robot.check_limit_table(data, f"limits file {path}")


def _sampled_magnitude(problem: DockingProblem, s: dict, kind) -> np.ndarray:
    """|the sampled quantity| that limit ``kind`` bounds, every joint (m, 8)
    (:func:`dockjax.robot.sampled_quantity`: travel about home)."""
    return np.abs(robot.sampled_quantity(s, kind, problem.home))


def _sampled_peaks(problem: DockingProblem, s: dict) -> np.ndarray:
    """Sampled ``max |quantity|`` of every limit column (8, kinds)."""
    return np.stack([_sampled_magnitude(problem, s, k).max(axis=0) for k in problem.kinds], axis=1)


def _sample_excess(problem: DockingProblem, s: dict) -> np.ndarray:
    """Sampled ``max |quantity| / limit − 1`` of every limit column (8, kinds)."""
    return _sampled_peaks(problem, s) / np.asarray(problem.limits) - 1.0


METHODS = ("direct",) + tuple(ALGORITHMS)
"""Plan methods: ``"direct"`` (default: shortest time by SQP, then the least-jerk front by
SQP) or an optimiser of :data:`dockjax.algorithms.ALGORITHMS` whose front is polished."""

BINDING = 1e-3
"""A limit binds when the plan's kernel column is within this fraction of the limit."""

FRONT_ITER = 60
"""SQP iterations per cap of a plan's front (the chosen point is then solved to convergence)."""

REPLAN_FRONT_ITER = 20
"""SQP iterations per cap of a replan's front (:meth:`Planner.replan`), each cap from the
replan's own shortest-time solution slowed to the cap. The template's points, made for
moves from rest, are farther from the least-jerk trajectories of a move that starts in
motion: over the 32 caps of the first four replans of ``benchmarks/bench_replan.py``, 30
iterations from them leave a cap's jerk 0.7 % above its converged value (median; at most
1.7 %), 20 from the slowed shortest-time solution 0.3 % (at most 0.7 %). The front
only chooses the point (Eq. 26), which is then solved to convergence; in the first 12
moves of ``benchmarks/bench_replan.py --moves 12``, 15, 20 and 30 iterations give the
choice and the plan of fronts solved to convergence."""

FD_STEP = 0.01
"""Relative change of a limit in the finite-difference check of its sensitivity."""


def _halved(problem: DockingProblem) -> int:
    """Half as many free control points as ``problem``'s family, at least the paper's five:
    a step of the continuation over families."""
    return max(config.N_FREE, problem.n_control // 2)


def _coarser(problem: DockingProblem) -> int:
    """The family (free control points) the shortest-time solve of a larger family starts
    from: with jerk limits :func:`_halved` (a continuation over families); without, the
    paper's five at once. Measured on the default move with knot
    intervals in [0.05, 30] s at 32 points (docs/planning.md): with jerk limits one jump from
    5 stalled at 15.78 s where doubling reached 15.2 s; without, both reach 12.06 s, and the
    jump costs one family's solves instead of three."""
    return _halved(problem) if problem.jerk is not None else config.N_FREE


def _shortest(problem: DockingProblem, x0=None, *, smooth: bool = True) -> solve.Solution:
    """The shortest-time solution, the least jerk among the shortest
    (:func:`dockjax.solve.shortest`; ``smooth=False``: the time programme's answer alone),
    from ``x0``. By default from the straight line at the shortest T the box allows, slowed
    until feasible; with more free control points than the paper's five, from the
    shortest plan of a coarser family (:func:`_coarser`: the paper's, or with jerk limits
    half as many points, recursively; its time programme's answer, not the least jerk among
    its shortest trajectories, which leads the finer time programme to slower answers),
    written exactly in the finer family (:func:`dockjax.solve.refine_family`), so that the
    SQP starts at a feasible trajectory near its optimum. Measured on the default move with
    knot intervals in [0.05, 30] s: 32 points reach 12.0578 s from the time optimum in
    13 s, 12.0600 s from the smoothed one in 21 s; with jerk limits, 16 points 15.219 s
    against 15.295 s. A move that some joint
    cannot make within the longest T, whatever the trajectory
    (:func:`dockjax.solve.floor_infeasibility`), fails at once."""
    if (floor := solve.floor_infeasibility(problem)) is not None:
        raise floor
    if x0 is None and problem.n_control > config.N_FREE and not problem.reduced:
        coarse = problem.with_n_control(_coarser(problem))
        try:
            x0 = solve.refine_family(problem, coarse, _shortest(coarse, smooth=False).x)
        except PlanError:
            x0 = None
    line = solve.straight_line(problem, [problem.n_intervals * problem.interval_bounds[0]])[0]
    solver = solve.shortest if smooth else solve.min_time
    sol = solver(problem, line if x0 is None else x0)
    if sol is None and x0 is not None:  # the finer family's solve failed from its start: from the line
        sol = solver(problem, line)
    if sol is None:
        raise solve.infeasibility(problem)
    return sol


def _caps(t_min: float, t_max: float, n: int) -> np.ndarray:
    """``n`` time caps from t_min to t_max, geometrically spaced (denser where the front is
    steep); t_min itself is the shortest-time solution, not a cap."""
    return np.geomspace(t_min, t_max, n + 1)[1:] if t_max > t_min * (1 + 1e-9) else np.zeros(0)


def _direct_front(problem: DockingProblem, n_front: int, shortest=None, on_cap=None, seeds=None,
                  max_iter: int = FRONT_ITER):
    """``(shortest, [least-jerk solutions at n_front caps up to the longest T])``, the front
    by continuation from the shortest-time solution, or from ``seeds`` (n_front, n_var) when
    given (:func:`dockjax.solve.least_jerk_front`; one SQP solve per cap of at most
    ``max_iter`` iterations; ``on_cap`` is called after each)."""
    shortest = _shortest(problem) if shortest is None else shortest
    caps = _caps(shortest.F[0], problem.n_intervals * problem.interval_bounds[1], n_front)
    return shortest, solve.least_jerk_front(problem, shortest, caps, line=False, max_iter=max_iter, restarts=0,
                                            on_cap=on_cap, seeds=seeds)


def _choice(problem: DockingProblem, sols: list, w, on_solve=None) -> solve.Solution:
    """The point of the front ``sols`` (the shortest-time solution first, then each cap's)
    with the best weighted satisfaction (Eq. 26 over the front's own ends), its cap's
    programme solved on from it (:func:`dockjax.solve.min_jerk`, up to 200 SLSQP iterations,
    no restarts; the lower jerk kept); the shortest-time solution for a zero jerk weight. ``on_solve`` is called
    after that solve. :func:`plan` and :meth:`Planner.plan` choose here, so that they agree."""
    if w[1] == 0 or len(sols) == 1:
        return sols[0]
    chosen = sols[select.choose(np.array([s.F for s in sols]), w)]
    if chosen is sols[0]:
        return chosen
    better = solve.min_jerk(problem, chosen.x, float(chosen.F[0]), restarts=0)
    if on_solve is not None:
        on_solve()
    return better if better is not None and better.F[1] < chosen.F[1] else chosen


def _optimiser_front(problem, method, pop_size, n_iter, seed, refine_steps):
    """The feasible non-dominated front of one optimiser run, polished by refine."""
    res = optimize(method, problem, seeds=[seed], pop_size=pop_size, n_iter=n_iter)
    m = res.front[0]
    if not m.any():
        j = int(np.argmin(res.cv[0]))
        G = robot.by_kind(res.G[0][j], problem.n_joints)
        jj, kk = np.unravel_index(np.argmax(G), G.shape)
        raise PlanError.of_column(
            problem, int(jj), int(kk), f"no feasible trajectory found by {method}: the limit {{limit}} cannot be met "
            f"(best candidate exceeds it by {100 * G[jj, kk]:.1f} %; T is at most "
            f"{problem.n_intervals * problem.interval_bounds[1]:g} s with interval bounds {problem.interval_bounds})",
            excess=float(G[jj, kk]))
    F, X = res.F[0][m], res.X[0][m]
    F, idx = nondominated_points(F, return_index=True)
    X = X[idx]
    if refine_steps:
        r = polish(problem, X, steps=refine_steps)
        keep = r.feasible & r.improved
        X = np.concatenate([X, r.X[keep]])
        F, idx = nondominated_points(np.concatenate([F, r.F[keep]]), return_index=True)
        X = X[idx]
    return X, F


def _certify(problem: DockingProblem, x, rate: float) -> dict:
    """The trajectory of ``x`` sampled at ``rate``, once certified: every sampled quantity
    and every kernel column (never understated) within its limit, else :class:`PlanError`
    naming the worst column."""
    s = problem.decode(x).sample(rate)
    g = robot.by_kind(problem.evaluate(np.asarray(x)[None], screen=False)[1][0], problem.n_joints)
    excess = np.maximum(_sample_excess(problem, s), g)
    if excess.max() > 0:
        j, k = np.unravel_index(np.argmax(excess), excess.shape)
        raise PlanError.of_column(problem, int(j), int(k), "the chosen trajectory fails {limit} by "
                                  f"{100 * excess[j, k]:.2f} % (certificate)", excess=float(excess[j, k]))
    return s


def _resolve(problem, sol: solve.Solution, cap):
    """Solve the programme of ``sol`` again (warm) on ``problem``: shortest time when cap is
    None, else least jerk at ``cap``."""
    if cap is None:
        return solve.min_time(problem, sol.x)
    return solve.min_jerk(problem, sol.x, cap)


def explain(problem: DockingProblem, sol: solve.Solution, samples: dict, *, time_optimal: bool,
            check: bool = True) -> dict:
    """Which limits bind and what each is worth.

    A limit binds when its kernel column is within :data:`BINDING` of it; its time is where
    the sampled quantity peaks. ``sensitivity`` is ``d T_min / d limit`` (s per limit
    unit) for the shortest-time plan, ``d jerk / d limit`` at fixed T otherwise, from the
    optimum's Lagrange multipliers (:func:`dockjax.solve.sensitivities`); with ``check``,
    ``finite_difference`` re-plans with the limit changed by ``± FD_STEP`` (central
    difference). For a fixed-T plan ``d_jerk_d_T`` is the value of time (the multiplier of
    the cap), checked the same way."""
    sens = solve.sensitivities(problem, sol)
    G = robot.by_kind(sol.G, problem.n_joints)
    cap = None if time_optimal else float(sol.F[0])
    objective = 0 if time_optimal else 1
    lim = np.asarray(problem.limits)
    keys = [kind.name for kind in problem.kinds]
    rows = []
    for j, k in zip(*np.nonzero(G > -BINDING)):
        name = problem.joints[j].name
        series = _sampled_magnitude(problem, samples, problem.kinds[k])[:, j]
        row = {"limit": f"{name} {keys[k]}", "joint": name, "quantity": keys[k],
               "value": float(lim[j, k]), "unit": problem.joints[j].unit + problem.kinds[k].suffix,
               "ratio": float(G[j, k] + 1.0), "time_s": float(samples["t"][int(np.argmax(series))]),
               "sensitivity": float(sens[j, k]) if np.isfinite(sens[j, k]) else None}
        if check:
            vals = []
            for f in (1.0 + FD_STEP, 1.0 - FD_STEP):
                arr = np.array(getattr(problem, keys[k]), np.float64)
                arr[j] *= f
                other = _resolve(dataclasses.replace(problem, **{keys[k]: arr}), sol, cap)
                vals.append(np.nan if other is None else float(other.F[objective]))
            row["finite_difference"] = (vals[0] - vals[1]) / (2 * FD_STEP * lim[j, k])
        rows.append(row)
    h = np.asarray(sol.x[: problem.n_intervals])
    out = {"objective": "T_s" if time_optimal else "jerk", "binding": rows,
           "intervals_at_bounds": {"lower": int(np.sum(h <= problem.interval_bounds[0] * (1 + 1e-6))),
                                   "upper": int(np.sum(h >= problem.interval_bounds[1] * (1 - 1e-6))),
                                   "of": problem.n_intervals},
           "note": "sensitivity: d objective / d limit (objective units per limit unit)"}
    if any(r["sensitivity"] is None for r in rows):
        out["note"] += ("; null: unknown (the SQP did not improve on its start, which is kept and is not known to be "
                        "a stationary point)")
    if not time_optimal:
        value = float(-sol.cap_multiplier * sol.objective_scale)
        out["d_jerk_d_T"] = value if np.isfinite(value) else None
        if check:
            vals = []
            for f in (1.0 + FD_STEP, 1.0 - FD_STEP):
                other = solve.min_jerk(problem, solve.time_scale(problem, sol.x, f) if f > 1 else sol.x, cap * f)
                vals.append(np.nan if other is None else float(other.F[1]))
            out["d_jerk_d_T_finite_difference"] = (vals[0] - vals[1]) / (2 * FD_STEP * cap)
    return out


def check_move(problem: DockingProblem) -> None:
    """ValueError when the start is the goal, at rest at both: there is nothing to plan
    (every trajectory of the box that stays put is optimal, whatever its time)."""
    if problem.boundary is None and np.array_equal(np.asarray(problem.start), np.asarray(problem.goal)):
        raise ValueError(f"start and goal are the same pose {np.asarray(problem.start).tolist()}: there is no move "
                         "to plan")


def check_duration(problem: DockingProblem, duration) -> float | None:
    """:func:`plan`'s ``duration`` checked against the interval bounds (ValueError naming
    it): None, or a finite number of seconds no longer than the longest T the bounds allow
    (``(n + 1) × hi``, 6 × hi in the paper's family). Cheap: no JAX computation. A duration
    below the shortest feasible time is not bad input but a :class:`PlanError` of
    :func:`plan` (it takes a solve to know)."""
    if duration is None:
        return None
    d = checks.number("duration", duration, 0.0, open_lo=True)
    longest = problem.n_intervals * problem.interval_bounds[1]
    if d > longest:
        raise ValueError(f"duration {d:g} s is longer than the longest T = {longest:g} s the interval bounds "
                         f"{problem.interval_bounds} allow ({problem.n_intervals} intervals); "
                         "widen the interval bounds")
    return float(d)


def check_options(weights, rate, method, pop_size, n_iter, seed, refine_steps, n_front) -> tuple[np.ndarray, float]:
    """:func:`plan`'s options checked (ValueError naming the option) and resolved: the
    weights (2,) and the rate (Hz). Cheap: no JAX computation."""
    w = select.check_weights(weights, 2)
    rate = checks.rate(rate)
    checks.choice("method", method, METHODS)
    checks.integer("pop_size", pop_size, 4)
    checks.integer("n_iter", n_iter, 1)
    checks.integer("seed", seed, 0, 2**63 - 1)
    checks.integer("refine_steps", refine_steps, 0)
    checks.integer("n_front", n_front, 2, 200)
    return w, rate


def plan(problem: DockingProblem | None = None, *, weights=(1.0, 1.0), rate: float = config.RATE,
         method: str = "direct", pop_size: int = config.POP_SIZE, n_iter: int = config.N_ITER, seed: int = 0,
         refine_steps: int = config.PLAN_REFINE_STEPS, n_front: int = config.PLAN_FRONT,
         check_sensitivities: bool = True, duration: float | None = None, progress: bool = False) -> Plan:
    """Plan one certified trajectory for ``problem`` and explain it.

    ``method="direct"`` (default): the shortest time by SQP (:func:`dockjax.solve.min_time`),
    then the least jerk at ``n_front`` time caps up to the longest T
    (:func:`dockjax.solve.least_jerk_front`); an optimiser name (``"imocs"``, ...) runs it
    (``pop_size``, ``n_iter``, ``seed``), polishes its front with ``refine_steps`` of
    :mod:`dockjax.refine`, and solves the least jerk again at the chosen T. The front point
    with the best weighted satisfaction (Eq. 26, ``weights`` = (w_T, w_jerk)) is chosen; a
    weight of 0 on jerk gives the shortest-time plan. The choice is certified (sampled at
    ``rate`` and by the kernel's rigorous maxima) and explained (:func:`explain`; with
    ``check_sensitivities`` the sensitivities are checked by re-planning).

    ``duration`` (s): instead of a choice by weights, the least-jerk plan that takes exactly
    that long (to rounding; :func:`_of_duration`), for a move that must fit a fixed cycle.
    It must be at most the longest T the interval bounds allow (``(n + 1) × hi``, else
    ValueError); below the shortest feasible time, :class:`PlanError` names the limit that
    binds the shortest-time trajectory and that time.

    ``progress``: a bar on stderr naming the step under way (the shortest time, each cap of
    the front, the chosen point's solve, the certificate, the sensitivities' check) and
    counting the steps done; a plan of many control points takes minutes.

    Raises ValueError on bad input (before any work) and :class:`PlanError` when no
    trajectory meets the limits.
    """
    problem = problem or DockingProblem()
    if not isinstance(problem, DockingProblem):
        raise ValueError(f"problem must be a DockingProblem, got {type(problem).__name__}")
    w, rate = check_options(weights, rate, method, pop_size, n_iter, seed, refine_steps, n_front)
    check_move(problem)
    d = check_duration(problem, duration)
    with tqdm(desc="plan", unit="step", disable=not progress, file=sys.stderr, leave=False) as bar:
        return _plan(problem, w, rate, method, pop_size, n_iter, seed, refine_steps, n_front, check_sensitivities, d,
                     bar)


def _plan(problem, w, rate, method, pop_size, n_iter, seed, refine_steps, n_front, check_sensitivities, d,
          bar) -> Plan:
    """:func:`plan` after its checks; ``bar`` (a tqdm bar) names each step under way and counts it."""
    time_only = w[1] == 0
    bar.set_postfix_str("shortest time")
    shortest = _shortest(problem)
    bar.update()
    if d is not None and d < shortest.F[0]:
        raise _too_short(problem, shortest, d)
    if method == "direct" and d is not None and _finer(problem):
        # a larger family's plan of a given duration starts from the coarser family's (the
        # continuation of _of_duration); a front would only add the dearest solves
        sols, front_F, chosen = [shortest], shortest.F[None], shortest
    elif method == "direct":
        bar.set_postfix_str(f"least jerk at {n_front} time caps")
        _, front = _direct_front(problem, n_front, shortest, on_cap=bar.update)
        sols = [shortest] + front
        front_F = np.array([s.F for s in sols])
        bar.set_postfix_str("the chosen point's least jerk")
        chosen = shortest if d is not None else _choice(problem, sols, w, on_solve=bar.update)
    else:
        bar.set_postfix_str(f"{method}, {n_iter} iterations")
        X, F = _optimiser_front(problem, method, pop_size, n_iter, seed, refine_steps)
        bar.update()
        chosen = shortest
        if not time_only and d is None:
            j = select.choose(F, w)
            bar.set_postfix_str("the chosen point's least jerk")
            chosen = solve.least_jerk(problem, float(F[j, 0]), [X[j]])
            bar.update()
            if chosen is None:
                raise PlanError(f"the least-jerk solve at T = {F[j, 0]:.6g} s found no certified trajectory")
        front_F = np.concatenate([F, chosen.F[None], shortest.F[None]])
    time_only = chosen is shortest
    if d is not None:
        found = [shortest.x] + ([s.x for s in sols[1:]] if method == "direct" else list(X))
        T_found = np.array([shortest.F[0]] + ([s.F[0] for s in sols[1:]] if method == "direct" else list(F[:, 0])))
        bar.set_postfix_str(f"least jerk at {d:g} s")
        chosen, time_only = _of_duration(problem, d, shortest, found, T_found)
        bar.update()
        front_F = np.concatenate([np.asarray(front_F, np.float64), chosen.F[None]])
    bar.set_postfix_str("certifying")
    samples = _certify(problem, chosen.x, rate)
    bar.update()
    bar.set_postfix_str("checking the sensitivities" if check_sensitivities else "explaining")
    why = explain(problem, chosen, samples, time_optimal=time_only, check=check_sensitivities)
    bar.update()
    settings = {"weights": list(map(float, w)), "rate": rate, "method": method, "n_front": n_front,
                "shortest_T_s": float(shortest.F[0])}
    if d is not None:
        settings = {"duration_s": d, **{k: v for k, v in settings.items() if k != "weights"}}
    if method != "direct":
        settings.update(pop_size=pop_size, n_iter=n_iter, seed=seed, refine_steps=int(refine_steps))
    F = nondominated_points(np.asarray(front_F, np.float64))
    return Plan(problem, problem.decode(chosen.x), chosen.x, float(chosen.F[0]), float(chosen.F[1]), F,
                samples, rate, tuple(w), settings, why)


def _too_short(problem: DockingProblem, shortest: solve.Solution, duration: float) -> PlanError:
    """The :class:`PlanError` of a duration below the shortest feasible time: names the
    limit that binds the shortest-time trajectory (the binding column worth the most time,
    by its sensitivity), or the interval bounds when no limit binds, and the time."""
    T = float(shortest.F[0])
    head = f"no trajectory takes {duration:g} s: the shortest feasible time is {T:.6g} s"
    G = robot.by_kind(shortest.G, problem.n_joints)
    sens = np.abs(solve.sensitivities(problem, shortest)) * (G > -BINDING)
    if np.isnan(sens).any():  # sensitivities unknown: the binding column nearest its limit
        sens = np.where(G > -BINDING, G + 1.0, 0.0)
    if sens.max() > 0:
        j, k = np.unravel_index(np.argmax(sens), sens.shape)
        return PlanError.of_column(problem, int(j), int(k), head + ", bound by the limit {limit}",
                                   excess=float(G[j, k]))
    return PlanError(head + f", bound by the interval bounds {problem.interval_bounds} "
                     f"(every interval at least {problem.interval_bounds[0]:g} s)")


def _finer(problem: DockingProblem) -> bool:
    """Whether ``problem``'s family starts its solves from a coarser family's (more free
    control points than the paper's five, not reduced)."""
    return problem.n_control > config.N_FREE and not problem.reduced


def _of_duration(problem: DockingProblem, T: float, shortest: solve.Solution, found, T_found):
    """The least-jerk certified solution that takes exactly ``T`` seconds (``T`` at least
    the shortest time): :func:`_least_jerk_of_duration` from the found trajectory with the
    longest time up to ``T`` slowed to it (exact time scaling keeps it feasible) or, in a
    family larger than the paper's, from the coarser family's plan of that duration
    (:func:`_coarse_duration`), where there is one. Near the shortest time (within
    :data:`dockjax.solve.SHORTEST_SLACK`) the shortest-time trajectory is slowed instead.
    → ``(solution, time_optimal)``."""
    if T <= shortest.F[0] * (1 + solve.SHORTEST_SLACK):
        return _exactly(problem, shortest, T), True
    T_found = np.asarray(T_found, np.float64)
    i = int(np.argmax(np.where(T_found <= T, T_found, -np.inf)))
    starts = _coarse_duration(problem, T) or [solve.time_scale(problem, found[i], T / T_found[i])]
    sol = _least_jerk_of_duration(problem, T, starts)
    if sol is None:
        raise PlanError(f"the least-jerk solve at T = {T:.6g} s found no certified trajectory of that duration")
    return sol, False


def _coarse_duration(problem: DockingProblem, T: float) -> list[np.ndarray]:
    """The start a larger family's plan of duration ``T`` takes from a coarser family
    (:func:`_halved`, down to the paper's five: a continuation over families, with or
    without jerk limits):
    that family's least-jerk trajectory of duration ``T``, written exactly in ``problem``'s
    family (:func:`dockjax.solve.refine_family`). Empty for the paper's family and smaller,
    and where the coarser family has no trajectory of that duration."""
    if not _finer(problem):
        return []
    coarse = problem.with_n_control(_halved(problem))
    T = T * (1.0 - COARSE_MARGIN)
    try:
        if _finer(coarse):
            starts = _coarse_duration(coarse, T)
        else:
            short = _shortest(coarse, smooth=False)
            starts = [solve.time_scale(coarse, short.x, T / short.F[0])] if short.F[0] <= T else []
    except PlanError:
        return []
    sol = _least_jerk_of_duration(coarse, T, starts) if starts else None
    x = None if sol is None else solve.refine_family(problem, coarse, sol.x)
    return [] if x is None else [x]


COARSE_MARGIN = 1e-9
"""A coarser family's plan in :func:`_coarse_duration` takes this much (relative) less than
the duration asked, so that the rounding of its writing in the finer family cannot carry it
over (the finer plan slows it to the duration exactly)."""


def _least_jerk_of_duration(problem: DockingProblem, T: float, starts) -> solve.Solution | None:
    """The lowest-jerk certified solution of exactly ``T`` seconds from ``starts`` (each
    (n_var,), taking at most ``T``): :func:`dockjax.solve.least_jerk` at the cap ``T``; where
    the certificate slowed its answer beyond ``T``, the cap is lowered by as much and solved
    again, while that answer is smoother than every certified start (a shorter cap only
    adds jerk). Every answer, and every start the kernel certifies, is slowed to exactly
    ``T`` by exact time scaling (at least 1: a hair, as a solve stops a hair inside its
    cap), which lowers every rate and the jerk; the lowest jerk wins, so the answer is never
    jerkier than a certified start. The straight line of duration ``T`` counts as a start
    (where the others slowed to ``T`` would cut an interval at its upper bound, it may fit).
    None when nothing certified takes exactly ``T``."""
    line = solve.straight_line(problem, T)[0]
    certified = (solve.certify_scaling(problem, x) for x in [*starts, line])
    exact = [_exactly(problem, solve.kept_start(problem, c), T) for c in certified
             if c is not None and c[1][0] <= T * (1 + DURATION_SLACK)]
    exact = [s for s in exact if _takes(s, T)]
    start_jerk = min((s.F[1] for s in exact), default=np.inf)
    cap, tried = T * (1 - DURATION_ROOM), list(starts)
    for _ in range(3):
        sol = solve.least_jerk(problem, cap, tried)
        if sol is None:
            break
        if sol.F[0] <= T * (1 + DURATION_SLACK):
            exact.append(_exactly(problem, sol, T))
            break
        if sol.F[1] >= start_jerk:
            break
        cap *= T / sol.F[0]
        tried = [sol.x]
    exact = [s for s in exact if _takes(s, T)]
    return min(exact, key=lambda s: s.F[1]) if exact else None


DURATION_ROOM = 1e-7
"""The least-jerk solve of a duration T caps the time at ``T (1 − DURATION_ROOM)``, room for
the certificate's time scaling; the answer is then slowed to exactly T, and where the
certificate slowed it beyond T the cap is lowered and the solve repeated
(:data:`dockjax.bulk.DURATION_ROOM` is wider, as the batched solve is not repeated)."""
DURATION_SLACK = 1e-9
"""A certified trajectory at most this fraction longer than a duration T (the certificate's
time scaling, a rounding) is sped up to exactly T and certified again there."""


def _takes(sol: solve.Solution, T: float) -> bool:
    """Whether ``sol`` is certified and takes exactly ``T`` (slowing it to ``T`` may have cut
    an interval at its upper bound, leaving it shorter)."""
    return bool(np.all(sol.G <= 0)) and abs(sol.F[0] - T) <= 1e-9 * T


def _exactly(problem: DockingProblem, sol: solve.Solution, T: float) -> solve.Solution:
    """``sol`` time-scaled to take exactly ``T`` (at least its time, or at most
    :data:`DURATION_SLACK` less), its F and G evaluated again."""
    x = solve.time_scale(problem, sol.x, T / float(np.sum(sol.x[: problem.n_intervals])))
    x[: problem.n_intervals] = np.minimum(x[: problem.n_intervals], problem.upper[: problem.n_intervals])
    F, G = problem.evaluate(x[None], screen=False)
    return dataclasses.replace(sol, x=x, F=F[0], G=G[0])


TEMPLATE_FORMAT = 1
"""Version of the layout of a stored :func:`template` (part of its key)."""


def template_key(problem: DockingProblem, n_front: int) -> str:
    """The key of :func:`template`'s front (hex SHA-256): the problem's identity,
    ``n_front``, :data:`TEMPLATE_FORMAT`, the package's sources and NumPy's and SciPy's
    versions (the solver's)."""
    text = json.dumps({"format": TEMPLATE_FORMAT, "problem": problem.identity(), "n_front": int(n_front),
                       "sources": store.source_digest(), "numpy": np.__version__, "scipy": scipy.__version__},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def template(problem: DockingProblem, n_front: int) -> np.ndarray:
    """The front a :class:`Planner` carries over to new poses: the decision vectors
    (1 + n_front, n_var) of the shortest-time solution and of the least-jerk solutions at
    ``n_front`` caps (:func:`_direct_front`). Loaded from the store of compiled programs
    (:func:`dockjax.store.folder`) when an earlier process solved the same problem
    (:func:`template_key`; checksummed file), else solved and saved there; the same bits
    either way (the solves are deterministic)."""
    where = store.folder()
    key = template_key(problem, n_front)
    path = None if where is None else where / f"{key}.template.npz"
    if path is not None and path.exists():
        try:
            d = load_npz(path, require_checksum=True)
            if str(d["key"]) == key:
                store.touch(path)
                return d["X"]
        except (DamagedFileError, KeyError):
            pass  # solved again and replaced
    shortest, front = _direct_front(problem, n_front)
    X = np.array([shortest.x] + [s.x for s in front])
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_savez(path, {"X": X, "key": np.array(key)})
            store.prune(where)
        except OSError:  # a read-only folder: kept in memory only
            pass
    return X


class Planner:
    """Plans for many start and goal poses of one problem shape, fast once warm, each the
    plan :func:`plan` would give.

    The first :meth:`plan` solves the problem given to the constructor in full
    (:func:`plan`'s ``"direct"`` method) and keeps its front as a template (:func:`template`:
    saved in the store of compiled programs, so a new process loads it). Every later call
    solves the new move's own front as :func:`plan` does (the shortest time, then the least
    jerk at the same ``n_front`` caps up to the longest T): the shortest time from the
    straight line, as :func:`plan` solves it, and from the template's shortest-time point
    carried over to the new poses (:func:`dockjax.solve.map_to`), the shorter kept (the time
    programme is not convex); each cap warm from the template's point carried over, instead
    of from the previous cap; then it chooses by Eq. 26 over that front
    and solves the chosen cap once more (:func:`_choice`, shared with :func:`plan`): the
    same front ends, the same normalisation, the same point. The answer is certified like
    :func:`plan`'s; its explanation carries the multiplier sensitivities (no re-planning).

    ``problem``: the template (default :class:`DockingProblem`); start and goal of later
    calls replace its own, every other field is kept.
    """

    def __init__(self, problem: DockingProblem | None = None, *, rate: float = config.RATE,
                 n_front: int = config.PLAN_FRONT):
        self.problem = problem or DockingProblem()
        if not isinstance(self.problem, DockingProblem):
            raise ValueError(f"problem must be a DockingProblem, got {type(self.problem).__name__}")
        self.rate = checks.rate(rate)
        self.n_front = checks.integer("n_front", n_front, 2, 200)
        self._template: np.ndarray | None = None

    def _problem_for(self, start, goal) -> DockingProblem:
        """The template with another start and goal (home: their midpoint, as by default)."""
        p = self.problem
        if start is None and goal is None:
            return p
        fields = p.identity()
        fields.pop("home")
        fields.update(start=p.start if start is None else start, goal=p.goal if goal is None else goal)
        return DockingProblem(**fields)

    def warm(self) -> "Planner":
        """Solve the template problem (or load its front from the store of an earlier
        process, :func:`template`) and compile the sampling of every trajectory length the
        interval bounds allow (the first :meth:`plan` does it otherwise)."""
        if self._template is None:
            self._template = template(self.problem, self.n_front)
            # samples are computed in buckets of lengths: one trajectory per bucket compiles them all
            t_lo, t_hi = (self.problem.n_intervals * b for b in self.problem.interval_bounds)
            for T in bucket_durations(t_lo, t_hi, self.rate):
                self.problem.decode(solve.straight_line(self.problem, [T])[0]).sample(self.rate)
            # the carrying over and its certification (the solves are the template's programmes)
            solve.certify_scaling(self.problem, solve.map_to(self.problem, self.problem, self._template)[0])
        return self

    def plan(self, start=None, goal=None, *, weights=(1.0, 1.0)) -> Plan:
        """A certified plan from ``start`` to ``goal`` (6,) (default: the template's), chosen
        by ``weights`` (w_T, w_jerk) as in :func:`plan` (a zero jerk weight: the shortest
        time, no front). Raises ValueError on bad input and :class:`PlanError` when no
        trajectory is found."""
        w = select.check_weights(weights, 2)
        problem = self._problem_for(start, goal)
        check_move(problem)
        return self._solve(problem, w)

    def replan(self, plan: Plan, t: float, goal=None, *, weights=None) -> Plan:
        """A certified plan from the state of ``plan`` at its time ``t`` (s, in [0, T]): its
        pose, velocity and acceleration (``start_velocity`` and ``start_acceleration`` of
        the new problem), to ``goal`` (6,) (default ``plan``'s), with ``plan``'s home,
        limits and interval bounds, chosen by ``weights`` (default ``plan``'s). The new
        plan's time 0 is ``plan``'s time ``t``: followed one after the other, the two are
        continuous in position, velocity and acceleration (the new spline's first control
        points are solved from that state, :func:`dockjax.bspline.control_points`).
        ``plan`` must be of this planner's spline family (its ``n_control``). Solved as
        :meth:`plan` solves, except that each cap of the front starts from the new move's
        shortest-time solution slowed to the cap, with at most :data:`REPLAN_FRONT_ITER` SQP
        iterations."""
        if not isinstance(plan, Plan):
            raise ValueError(f"plan must be a Plan, got {type(plan).__name__}")
        if plan.problem.n_control != self.problem.n_control:
            raise ValueError(f"plan has n_control={plan.problem.n_control}, this planner "
                             f"{self.problem.n_control}: replan with a Planner of the plan's problem")
        w = select.check_weights(plan.weights if weights is None else weights, 2)
        t = checks.number("t", t, 0.0, plan.T)
        pose, velocity, acceleration = (plan.trajectory.pose([t], k)[0] for k in range(3))
        fields = plan.problem.identity()
        fields.update(start=pose, start_velocity=velocity, start_acceleration=acceleration,
                      goal=plan.problem.goal if goal is None else goal)
        problem = DockingProblem(**fields)
        check_move(problem)
        return self._solve(problem, w, in_motion=True, replanned_at_s=float(t))

    def _solve(self, problem: DockingProblem, w, in_motion: bool = False, **extra) -> Plan:
        """:meth:`plan`'s solve of ``problem`` (checked) at weights ``w``: the shortest time
        from the straight line and from the template's point carried over; each cap of the
        front from the template's point carried over in at most :data:`FRONT_ITER` SQP
        iterations, or, ``in_motion``, from the shortest-time solution slowed to the cap in
        at most :data:`REPLAN_FRONT_ITER`; ``extra`` goes into the settings."""
        self.warm()
        X = solve.map_to(problem, self.problem, self._template)
        first = solve.certify_scaling(problem, X[0])
        # the time programme is not convex: from plan()'s own start (the straight line) and
        # from the template's shortest-time point where it certifies, the shorter kept (plan()'s
        # at a tie). The second start gets the least jerk among its shortest (the dear part)
        # only when its time programme alone ends shorter
        shortest, error = None, None
        for x0 in [None] + ([] if first is None else [first[0]]):
            try:
                if shortest is not None and _shortest(problem, x0, smooth=False).F[0] >= shortest.F[0] * (1 - 1e-9):
                    continue
                found = _shortest(problem, x0)
                if shortest is None or found.F[0] < shortest.F[0] * (1 - 1e-9):
                    shortest = found
            except PlanError as e:
                error = error or e
        if shortest is None:
            raise error
        sols = [shortest]
        if w[1] != 0:
            if in_motion:  # the template's points are moves from rest; this move's own shortest is nearer
                seeds, front_iter = np.repeat(shortest.x[None], self.n_front, 0), REPLAN_FRONT_ITER
            else:  # a template cap without an answer: by continuation
                seeds, front_iter = (X[1:] if len(X) == self.n_front + 1 else None), FRONT_ITER
            sols += _direct_front(problem, self.n_front, shortest, seeds=seeds, max_iter=front_iter)[1]
        chosen = _choice(problem, sols, w)
        samples = _certify(problem, chosen.x, self.rate)
        why = explain(problem, chosen, samples, time_optimal=chosen is shortest, check=False)
        settings = {"weights": list(map(float, w)), "rate": self.rate, "method": "planner", "n_front": self.n_front,
                    "shortest_T_s": float(shortest.F[0]), **extra}
        return Plan(problem, problem.decode(chosen.x), chosen.x, float(chosen.F[0]), float(chosen.F[1]),
                    nondominated_points(np.array([s.F for s in sols])), samples, self.rate, tuple(w), settings,
                    why)


def explain_text(why: dict) -> str:
    """The explanation of :func:`explain` as lines of text."""
    obj = "T_min [s]" if why["objective"] == "T_s" else "jerk"
    lines = [f"binding limits (within {100 * BINDING:g} % of the limit) and d {obj} / d limit:"]
    if not why["binding"]:
        lines.append("  none")
    for r in why["binding"]:
        fd = r.get("finite_difference")
        check = f"   re-planned ±{100 * FD_STEP:g} %: {fd:+.5g}" if fd is not None else ""
        value = "unknown" if r["sensitivity"] is None else f"{r['sensitivity']:+.5g} per {r['unit']}"
        lines.append(f"  {r['limit']:<24} {r['value']:g} {r['unit']:<7} at t = {r['time_s']:7.3f} s   "
                     f"{value}{check}")
    low = why.get("intervals_at_bounds", {}).get("lower", 0)
    if low:
        of = why["intervals_at_bounds"].get("of", config.N_INTERVALS)
        lines.append(f"  {low} of the {of} knot intervals at their lower bound (--interval-bounds)")
    if "d_jerk_d_T" in why:
        fd = why.get("d_jerk_d_T_finite_difference")
        check = f"   re-planned ±{100 * FD_STEP:g} %: {fd:+.5g}" if fd is not None else ""
        value = "unknown" if why["d_jerk_d_T"] is None else f"{why['d_jerk_d_T']:+.5g} per s"
        lines.append(f"  value of time: d jerk / d T = {value}{check}")
    return "\n".join(lines)


def write_plan(p: Plan, out: str | Path, export: tuple[str, ...] = ()) -> list[Path]:
    """Write trajectory.csv, summary.json, front.png, trajectory.png and, when a binding
    limit is worth something, limits.png (:func:`dockjax.plots.worth_drawing`) into ``out``
    as one set (:func:`dockjax.io.write_set`): a failure while writing leaves the previous
    plan's files untouched, and files of an earlier plan that this one does not write
    (limits.png, exports) are removed. ``export``: any of :data:`dockjax.export.EXPORTS`:
    ``"ros2"`` adds trajectory_ros2.yaml and trajectory_ros2.json (a ROS 2
    ``JointTrajectory``, :func:`dockjax.export.joint_trajectory`), ``"axes"`` one
    axis-<joint>.csv per joint (:func:`dockjax.export.axis_tables`), both at the plan's rate."""
    export = tuple(export)
    unknown = [e for e in export if e not in EXPORTS]
    if unknown:
        raise ValueError(f"export must be any of {', '.join(EXPORTS)}, got {', '.join(map(repr, unknown))}")
    if export and p.problem.supports is not None:
        raise ValueError(f"exports are for the paper's two arms; this cabin has {p.problem.n_supports} supports")
    return write_set(out, lambda stage: _write_plan_files(p, stage, export), owned=PLAN_FILES)


ROS2_FILES = ("trajectory_ros2.yaml", "trajectory_ros2.json")
AXIS_FILES = tuple(f"axis-{name}.csv" for name in config.JOINT_NAMES)
PLAN_FILES = ("trajectory.csv", "summary.json", "front.png", "trajectory.png", "limits.png", *ROS2_FILES, *AXIS_FILES)
"""Every file :func:`write_plan` may write."""


def _write_plan_files(p: Plan, out: Path, export: tuple[str, ...] = ()) -> list[Path]:
    files = [p.trajectory.to_csv(out / "trajectory.csv", p.rate)]
    if "ros2" in export:
        msg = joint_trajectory(p.trajectory, p.rate)
        for name, text in zip(ROS2_FILES, (to_yaml(msg), to_json(msg))):
            files.append(atomic_write_text(out / name, text))
    if "axes" in export:
        for name, text in zip(AXIS_FILES, axis_tables(p.trajectory, p.rate).values()):
            files.append(atomic_write_text(out / name, text))
    summary = {
        "dockjax_version": __version__,
        "T_s": p.T,
        "jerk": p.jerk,
        "x": p.x.tolist(),
        "front": p.front.tolist(),
        "explanation": p.explanation,
        "joints": p.margins(),
        "settings": {**p.settings, "start": p.problem.start.tolist(), "goal": p.problem.goal.tolist(),
                     "arm_distance": p.problem.arm_distance,
                     **({} if p.problem.supports is None else {"supports": p.problem.offsets.tolist()}),
                     "interval_bounds": list(p.problem.interval_bounds), "n_control": p.problem.n_control,
                     "limits": {q.name: p.problem.limits[:, k].tolist() for k, q in enumerate(p.problem.kinds)},
                     "home": p.problem.home.tolist()},
    }
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    files.append(out / "summary.json")
    method = p.settings.get("method", "direct")
    label = {"direct": "least-jerk front (SQP)", "planner": "planner (carried-over front)"}.get(
        method, method + ("+refine" if p.settings.get("refine_steps") else ""))
    files.append(plots.plot_fronts({label: p.front}, out / "front.png", highlight=(p.T, p.jerk),
                                   title=f"front and chosen point (T = {p.T:.2f} s)"))
    s = p.samples
    files.append(plots.plot_joints(s, p.problem.limits, out / "trajectory.png", home=p.problem.home,
                                   title=f"planned joints, T = {p.T:.2f} s, jerk = {p.jerk:.4g}"))
    if plots.worth_drawing(p.explanation):  # only where a limit is worth something
        files.append(plots.plot_sensitivities(p.explanation, out / "limits.png"))
    return files
