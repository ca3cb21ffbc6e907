"""Plans on the default move beside ruckig and toppra, warm replanning, and plans with more
control points and jerk limits beside ruckig.

python benchmarks/bench_plan.py [--repeats 7] [--replans 20] [--jerk-limits 25] [--n-front 8] [--peer-rate 10000]
                                [--figure docs/plan_peers.png] [--best-known 40 20 600] [--controls 5 16 32]
                                [--batches 1 10 100] [--batch-bounds 0.5 10] [--batch-slsqp 3] [--warmup 1]
python benchmarks/bench_plan.py --repeats 1 --replans 1 --jerk-limits 2 --n-front 2 --peer-rate 1e3 --controls 5 --batches 4 --batch-bounds 0.5 3 --batch-slsqp 1 --warmup 0 # quick

The default start and goal with paper Table 2 limits, knot intervals in [0.5, 10] s (the
``wide`` preset, where time is limited by the joints rather than by the box). Rows:

* dockjax, shortest time: :func:`dockjax.plan.plan` with weights (1, 0) (SQP on the spline
  family), and the compromise plan with weights (1, 1), chosen among the least-jerk plans at
  ``--n-front`` time caps (``n_front``, also the planner's below);
* ruckig (time-optimal, jerk-limited, per joint, time-synchronised), in joint space from the
  start's joints to the goal's, with a jerk limit of 1e6 (practically unlimited): the
  shortest time; and at dockjax's compromise T (``minimum_duration``), the least jerk
  objective over ``--jerk-limits`` jerk limits from 1 to 1e6 (log grid);
* toppra (time-optimal path parametrisation, velocity and acceleration limits) along the
  straight pose line mapped to the joints (201 waypoints, a cubic spline through them; the
  timed call builds the spline and solves).

For each: T, the jerk objective of Eq. 25 (sampled at ``--peer-rate`` Hz, default 10 kHz,
for the peers: the mean square of each joint's third derivative by finite differences of the
sampled acceleration), the largest ratio of |velocity| and |acceleration| to its limit
(sampled for the peers, the kernel's exact columns for dockjax), and the median time per
call (warm: after ``--warmup`` untimed calls that compile; 0 times the first call). Then a
:class:`dockjax.plan.Planner` replans ``--replans`` random start and goal poses (the
defaults ± 5 mm, ± 0.1°, ± 1° roll): median and largest time per call, the median time of
:func:`dockjax.plan.plan` on the same moves and how many of its choices the planner's
matches (T and jerk within 0.1 %), and the largest gap of its jerk to the least jerk found
at the same T from the straight line and from the planner's own answer
(:func:`dockjax.solve.least_jerk`). The front figure
(``--figure PATH``; ``--figure`` alone: ``plan_peers.png`` in a new temporary folder) shows
the best-known front (``--best-known``: its time caps, SQP anchors and refinement steps per
cap) with every peer's point. A peer that is not installed (ruckig and toppra come with the
``bench`` extra) is skipped with a line saying so.

The last table (``--controls``, no values to skip it) plans the shortest time with n free
control points on two moves, knot intervals in [0.05, 30] s (small enough for many
intervals): the default move with Table 2 limits, and the same move with jerk limits
:data:`JERK_LIMITS` per arm joint beside ruckig's time-optimal joint-space move under the
same velocity, acceleration and jerk limits. Per n: T, T over ruckig's, the largest sampled
|jerk| over its limit (at ``--peer-rate``) and the kernel's largest column (certified: at
most 0), and the wall time of one warm :func:`dockjax.plan.plan` call (``--n-front`` caps,
after ``--warmup`` untimed calls) and its ratio to the first n's.

The batch table (``--batches``, no values to skip it) plans B random moves (the default
start and goal ± 5 mm, ± 0.1°, seeded) with knot intervals in ``--batch-bounds`` by
:func:`dockjax.bulk.plan_batch` (weights (1, 1), ``--n-front`` caps): per B the first call
(compile and run; the compiled program is then kept in dockjax's store), the warm call, plans
per second, the moves found feasible, and the median SQP iterations; then the SLSQP planner
(:func:`dockjax.plan.plan`, warm) on the first ``--batch-slsqp`` moves, one at a time, for plans per second
and the largest relative gaps of T_min and of the chosen plan's T and jerk, and a
:class:`dockjax.plan.Planner` of the same problem on the feasible ones: its gaps to ``plan``,
and on how many moves the three choose the same point (T and jerk within 0.1 %).
"""

from __future__ import annotations

import argparse
import importlib
import tempfile
import time
from pathlib import Path

import numpy as np

from dockjax import config, plots
from dockjax.best_known import best_known_front
from dockjax.bulk import plan_batch
from dockjax.kinematics import inverse_kinematics
from dockjax.plan import Planner, plan
from dockjax.problem import DockingProblem, make_problem
from dockjax.robot import by_kind
from dockjax.solve import least_jerk

RATE = 10_000.0
JERK_LIMITS = (10.0, 10.0, 1.0, 10.0)
"""Jerk limits per arm joint of the last table (axial, lift, lateral in mm/s³; roll in °/s³)."""
N_CONTROL_BOUNDS = (0.05, 30.0)
"""Interval bounds of the last table's plans (s)."""


def _median_time(fn, repeats):
    out, times = None, []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, float(np.median(times))


def _sampled_scores(t, q, v, a, limits):
    """T, Eq. 25 jerk objective, max |v|/limit, max |a|/limit of sampled joints (m, 8)."""
    T = float(t[-1])
    dt = np.diff(t)
    j = np.diff(a, axis=0) / dt[:, None]
    ms = np.sum(j ** 2 * dt[:, None], 0) / T
    return T, float(np.sum(np.sqrt(ms))), float(np.max(np.abs(v) / limits[:, 1])), \
        float(np.max(np.abs(a) / limits[:, 2]))


def _peer(name: str, skipped: list[str]):
    """The peer's module, or None with the reason appended to ``skipped`` when it is not
    importable."""
    try:
        return importlib.import_module(name)
    except ImportError as exc:
        skipped.append(f"{name} skipped: it is not importable ({exc}); pip install 'dockjax[bench]'")
        return None


def _ruckig(q0, q1, limits, jerk_limit, duration=None):
    """ruckig's time-synchronised move from rest at q0 to rest at q1 under the velocity and
    acceleration columns of ``limits`` (8, kinds) and ``jerk_limit`` (a number or 8)."""
    import ruckig

    n = len(q0)
    inp = ruckig.InputParameter(n)
    inp.current_position, inp.target_position = list(q0), list(q1)
    inp.current_velocity = inp.current_acceleration = [0.0] * n
    inp.target_velocity = inp.target_acceleration = [0.0] * n
    inp.max_velocity, inp.max_acceleration = list(limits[:, 1]), list(limits[:, 2])
    inp.max_jerk = list(np.broadcast_to(np.asarray(jerk_limit, np.float64), (n,)))
    if duration is not None:
        inp.minimum_duration = float(duration)
    traj = ruckig.Trajectory(n)
    ruckig.Ruckig(n).calculate(inp, traj)
    return traj


def _ruckig_samples(traj, rate):
    t = np.arange(0.0, traj.duration, 1.0 / rate)
    t = np.append(t, traj.duration)
    pva = [traj.at_time(float(s)) for s in t]
    q, v, a = (np.array([p[k] for p in pva]) for k in range(3))
    return t, q, v, a


def _straight_joint_path(problem, n=201):
    """Waypoints (n, 8) of the straight pose line from start to goal, mapped to the joints."""
    s = np.linspace(0.0, 1.0, n)
    poses = problem.start + s[:, None] * (problem.goal - problem.start)
    return s, np.asarray(inverse_kinematics(poses, problem.arm_distance))


def _toppra(waypoints, limits):
    import toppra as ta
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    ta.setup_logging("WARNING")
    path = ta.SplineInterpolator(*waypoints)
    cons = [constraint.JointVelocityConstraint(limits[:, 1]),
            constraint.JointAccelerationConstraint(limits[:, 2])]
    return algo.TOPPRA(cons, path, parametrizer="ParametrizeConstAccel").compute_trajectory()


def _toppra_samples(traj, rate):
    t = np.append(np.arange(0.0, traj.duration, 1.0 / rate), traj.duration)
    return t, traj(t), traj(t, 1), traj(t, 2)


def _warm(fn, warmup: int):
    """``fn()`` called ``warmup`` times, untimed (the first call compiles)."""
    for _ in range(warmup):
        fn()


def _timed_plan(problem, rate, n_front, warmup: int = 1):
    """The shortest-time plan of ``problem`` (its front at ``n_front`` caps) and the wall time
    of a call after ``warmup`` untimed ones."""
    options = dict(weights=(1.0, 0.0), rate=rate, n_front=n_front, check_sensitivities=False)
    _warm(lambda: plan(problem, **options), warmup)
    t = time.perf_counter()
    p = plan(problem, **options)
    return p, time.perf_counter() - t


def n_control_table(n_controls, rate: float, skipped: list[str], n_front: int, warmup: int = 1) -> None:
    """The last table of the module docstring."""
    print(f"\nshortest time with n free control points, default move, intervals in {N_CONTROL_BOUNDS} s; "
          f"jerk limits {JERK_LIMITS} per arm joint beside ruckig under the same limits\n")
    print("| n | T, Table 2 limits [s] | plan time | vs first | T, with jerk limits [s] | T / ruckig's "
          "| max sampled jerk/limit | max G | plan time | vs first |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    ruck, first = None, None
    for n in n_controls:
        plain, t_plain = _timed_plan(DockingProblem(interval_bounds=N_CONTROL_BOUNDS, n_control=n), rate, n_front, warmup)
        problem = DockingProblem(interval_bounds=N_CONTROL_BOUNDS, n_control=n, jerk=JERK_LIMITS)
        p, t_jerk = _timed_plan(problem, rate, n_front, warmup)
        lim = np.asarray(problem.limits)
        if ruck is None and _peer("ruckig", skipped) is not None:
            q0 = np.asarray(inverse_kinematics(problem.start, problem.arm_distance))
            q1 = np.asarray(inverse_kinematics(problem.goal, problem.arm_distance))
            ruck = _ruckig(q0, q1, lim, lim[:, 3]).duration
        first = first or (t_plain, t_jerk)
        G = problem.evaluate(p.x[None], screen=False)[1][0]
        jerk_ratio = float(np.max(np.abs(p.samples["jerk"]) / lim[:, 3]))
        vs = f"{p.T / ruck:.4f}" if ruck else "—"
        print(f"| {n} | {plain.T:.3f} | {t_plain:.1f} s | {t_plain / first[0]:.2f} | {p.T:.3f} | {vs} "
              f"| {jerk_ratio:.4f} | {G.max():.2g} | {t_jerk:.1f} s | {t_jerk / first[1]:.2f} |")
    if ruck:
        print(f"\nruckig's time-optimal move under the jerk limits: T = {ruck:.3f} s")


def batch_table(batches, bounds, n_front: int, repeats: int, slsqp: int = 3, warmup: int = 1) -> None:
    """The batch table (module docstring)."""
    problem = DockingProblem(interval_bounds=bounds)
    rng = np.random.default_rng(0)
    step = np.array([5.0, 5.0, 5.0, 0.1, 0.1, 0.1])
    S = np.asarray(problem.start) + rng.uniform(-1, 1, (max(batches), 6)) * step
    G = np.asarray(problem.goal) + rng.uniform(-1, 1, (max(batches), 6)) * step
    print(f"plan_batch: random moves (default ± 5 mm, ± 0.1°), intervals in {bounds} s, weights (1, 1), "
          f"{n_front} caps\n")
    print("| B | first call [s] | warm call [s] | plans/s | feasible | SQP iterations (median) |")
    print("|---:|---:|---:|---:|---:|---:|")
    for B in batches:
        t = time.perf_counter()
        res = plan_batch(problem, S[:B], G[:B], n_front=n_front)
        first = time.perf_counter() - t
        res, dt = _median_time(lambda: plan_batch(problem, S[:B], G[:B], n_front=n_front),
                               repeats if B <= 10 else 1)
        print(f"| {B} | {first:.1f} | {dt:.2f} | {B / dt:.2f} | {int(res.feasible.sum())} | "
              f"{np.median(res.iterations):.0f} |")
    times, gaps, same = [], [], 0
    planner = Planner(problem, n_front=n_front).warm() if slsqp else None
    for i in range(min(slsqp, len(res))):
        one = res.move(i)
        if i == 0:
            _warm(lambda: plan(one, n_front=n_front, check_sensitivities=False), warmup)
        p, dt = _median_time(lambda: plan(one, n_front=n_front, check_sensitivities=False), 1)
        times.append(dt)
        if res.feasible[i]:
            q = planner.plan(one.start, one.goal)
            gaps.append([abs(res.T_min[i] / p.settings["shortest_T_s"] - 1), abs(res.T[i] / p.T - 1),
                         abs(res.jerk[i] / p.jerk - 1), abs(q.T / p.T - 1), abs(q.jerk / p.jerk - 1)])
            same += max(gaps[-1][1], gaps[-1][3]) <= 1e-3 and max(gaps[-1][2], gaps[-1][4]) <= 1e-3
    if times:
        g = np.max(gaps, axis=0) if gaps else [np.nan] * 5
        print(f"\nSLSQP planner (plan, warm), {len(times)} moves one at a time: median {np.median(times):.2f} s per "
              f"plan ({1 / np.median(times):.2f} plans/s); largest relative gaps to plan_batch: T_min {g[0]:.1e}, "
              f"chosen T {g[1]:.1e}, chosen jerk {g[2]:.1e}; to a Planner of the same problem: chosen T {g[3]:.1e}, "
              f"chosen jerk {g[4]:.1e}; plan, Planner and plan_batch choose the same point (T and jerk within 0.1 %) "
              f"for {same} of {len(gaps)} feasible moves\n")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--replans", type=int, default=20)
    ap.add_argument("--n-front", type=int, default=config.PLAN_FRONT,
                    help="time caps of the least-jerk front a plan chooses from (plan's and Planner's n_front)")
    ap.add_argument("--peer-rate", type=float, default=RATE, help="sampling rate of the peers' scores (Hz)")
    ap.add_argument("--jerk-limits", type=int, default=25,
                    help="ruckig's jerk limits tried at the compromise T (log grid from 1 to 1e6)")
    ap.add_argument("--figure", nargs="?", default=None, const="",
                    help="write the front with the peers' points here (alone: into a new temporary folder)")
    ap.add_argument("--best-known", type=int, nargs=3, default=[40, 20, 600], metavar=("POINTS", "ANCHORS", "STEPS"),
                    help="the figure's best-known front: time caps, SQP anchors, refinement steps per cap")
    ap.add_argument("--controls", type=int, nargs="*", default=[5, 16, 32],
                    help="free control points of the last table's plans (none: skip it)")
    ap.add_argument("--batches", type=int, nargs="*", default=[1, 10, 100],
                    help="batch sizes B of plan_batch (none: skip the batch table)")
    ap.add_argument("--batch-bounds", type=float, nargs=2, default=[0.5, 10.0], metavar=("LO", "HI"),
                    help="knot interval bounds of the batch table's moves (s)")
    ap.add_argument("--batch-slsqp", type=int, default=3,
                    help="moves of the batch table also planned by the SLSQP planner, one at a time")
    ap.add_argument("--warmup", type=int, default=1,
                    help="untimed calls of each dockjax plan before the timed ones (0: time the first, compiling call)")
    args = ap.parse_args(argv)
    if args.warmup < 0:
        ap.error(f"--warmup must be >= 0, got {args.warmup}")
    if min(args.repeats, args.replans, args.jerk_limits, args.batch_slsqp, *args.batches) < 1:
        ap.error("--repeats, --replans, --jerk-limits, --batches and --batch-slsqp must be >= 1")
    if not 0 < args.batch_bounds[0] < args.batch_bounds[1]:
        ap.error(f"--batch-bounds must satisfy 0 < LO < HI, got {args.batch_bounds}")
    if any(not 1 <= n <= config.MAX_CONTROL for n in args.controls):
        ap.error(f"--controls values must be from 1 to {config.MAX_CONTROL}, got {args.controls}")
    if not args.peer_rate > 0:
        ap.error(f"--peer-rate must be > 0, got {args.peer_rate}")
    if args.batches:
        batch_table(args.batches, tuple(args.batch_bounds), args.n_front, args.repeats, args.batch_slsqp, args.warmup)
    problem = make_problem("wide")
    lim = np.asarray(problem.limits)
    q0 = np.asarray(inverse_kinematics(problem.start, problem.arm_distance))
    q1 = np.asarray(inverse_kinematics(problem.goal, problem.arm_distance))
    rows = []

    def dockjax_row(label, weights):
        options = dict(weights=weights, n_front=args.n_front, check_sensitivities=False)
        _warm(lambda: plan(problem, **options), args.warmup)
        p, dt = _median_time(lambda: plan(problem, **options), args.repeats)
        g = by_kind(p.problem.evaluate(p.x[None], screen=False)[1][0])  # every column exact
        rows.append((label, p.T, p.jerk, float(np.max(g[:, 1] + 1)), float(np.max(g[:, 2] + 1)), dt))
        return p

    dockjax_row("dockjax, shortest time (SQP)", (1.0, 0.0))
    p_comp = dockjax_row("dockjax, compromise (1, 1)", (1.0, 1.0))
    notes: list[str] = []
    rate = args.peer_rate
    if _peer("ruckig", notes) is not None:
        traj, dt = _median_time(lambda: _ruckig(q0, q1, lim, 1e6), args.repeats)
        rows.append(("ruckig, shortest time (jerk limit 1e6)", *_sampled_scores(*_ruckig_samples(traj, rate), lim), dt))
        best = None
        for jl in np.geomspace(1.0, 1e6, args.jerk_limits):
            traj = _ruckig(q0, q1, lim, jl, duration=p_comp.T)
            if abs(traj.duration - p_comp.T) > 1e-6 * p_comp.T:
                continue
            sc = _sampled_scores(*_ruckig_samples(traj, rate), lim)
            if best is None or sc[1] < best[0][1]:
                best = (sc, jl)
        if best is not None:
            _, dt = _median_time(lambda: _ruckig(q0, q1, lim, best[1], duration=p_comp.T), args.repeats)
            rows.append((f"ruckig at the compromise T (jerk limit {best[1]:.3g})", *best[0], dt))
        else:
            notes.append(f"ruckig at the compromise T: none of the {args.jerk_limits} jerk limits reaches "
                         f"T = {p_comp.T:.3f} s exactly")
    if _peer("toppra", notes) is not None:
        waypoints = _straight_joint_path(problem)
        _warm(lambda: _toppra(waypoints, lim), args.warmup)
        out, dt = _median_time(lambda: _toppra(waypoints, lim), args.repeats)
        rows.append(("toppra, straight joint path", *_sampled_scores(*_toppra_samples(out, rate), lim), dt))

    print(f"default move, Table 2 limits, intervals in {problem.interval_bounds} s; median of {args.repeats} "
          f"calls after {args.warmup} untimed; peers sampled at {rate:g} Hz\n")
    print("| method | T [s] | jerk (Eq. 25) | max v/limit | max a/limit | time per call |")
    print("|---|---:|---:|---:|---:|---:|")
    for label, T, J, rv, ra, dt in rows:
        print(f"| {label} | {T:.3f} | {J:.4g} | {rv:.4f} | {ra:.4f} | {dt * 1e3:.3g} ms |")
    for note in notes:
        print(f"\n{note}")
    print(f"\nlateral joint floor (30 mm at 2.5 mm/s, 100 mm/s²): {30 / 2.5 + 2.5 / 100:.3f} s")

    # warm replanning
    planner = Planner(DockingProblem(), n_front=args.n_front)
    planner.plan()
    rng = np.random.default_rng(0)
    half = np.array([5, 5, 5, 0.1, 0.1, 1.0])
    times, gaps, full, same = [], [], [], 0
    for _ in range(args.replans):
        s = np.asarray(config.START) + rng.uniform(-1, 1, 6) * half
        g = np.asarray(config.GOAL) + rng.uniform(-1, 1, 6) * half
        t = time.perf_counter()
        p = planner.plan(s, g, weights=(1.0, 1.0))
        times.append(time.perf_counter() - t)
        ref = least_jerk(p.problem, p.T, [p.x])
        gaps.append(p.jerk / ref.F[1] - 1.0)
        t = time.perf_counter()
        q = plan(p.problem, weights=(1.0, 1.0), n_front=args.n_front, check_sensitivities=False)
        full.append(time.perf_counter() - t)
        same += abs(q.T - p.T) <= 1e-3 * q.T and abs(q.jerk - p.jerk) <= 1e-3 * q.jerk
    print(f"\nPlanner (default problem), {args.replans} random start/goal poses, weights (1, 1): "
          f"median {np.median(times) * 1e3:.1f} ms, largest {np.max(times) * 1e3:.1f} ms per plan "
          f"(plan() on the same moves: median {np.median(full):.2f} s); the same point as plan() "
          f"(T and jerk within 0.1 %) for {same} of {args.replans}; "
          f"jerk above the least jerk at its T by at most {100 * max(gaps):.2g} %")

    if args.figure is not None:  # --figure alone: plan_peers.png in a new temporary folder
        figure = Path(args.figure) if args.figure else Path(tempfile.mkdtemp(prefix="bench_plan-")) / "plan_peers.png"
        n_points, n_exact, steps = args.best_known
        front = best_known_front(problem, n_points=n_points, n_exact=n_exact, steps=steps)
        peers = {label: np.array([[T, J]]) for label, T, J, *_ in rows}
        plots.plot_fronts(peers, figure, reference=front.F, reference_label="dockjax best-known front",
                          title="default move, Table 2 limits: dockjax's front and the peers")
        print(f"wrote {figure}")

    if args.controls:
        skipped: list[str] = []
        n_control_table(args.controls, rate, skipped, args.n_front, args.warmup)
        for note in skipped:
            print(f"\n{note}")


if __name__ == "__main__":
    main()
