"""Replanning in motion: a warm ``Planner.replan`` from the state of a running plan against a warm ``Planner.plan``.

    python benchmarks/bench_replan.py [--moves 10] [--repeats 3] [--shift 0.3] [--at 0.333] [--figure replan.png]
    python benchmarks/bench_replan.py --moves 1 --repeats 1 --n-front 2 --rate 50 --figure replan.png  # quick

A warm :class:`dockjax.plan.Planner` of the default problem plans ``--moves`` random moves
(start and goal within ±5 mm and ±0.1° in pitch and yaw, ±1° in roll of the paper's; seed
0) and, for each, replans at ``--at`` × T to its goal moved by ``--shift`` mm along x.
Each move's plan and replan are timed ``--repeats`` times, one after the other in turn
(the machine's load falls on both alike), and each time is the median of its repeats.
Printed per move: the two wall times, their ratio, the largest jumps
where the plans join (position, velocity, acceleration of the pose, relative to the
largest value of that quantity over the first plan), and both plans' T; then the medians.
With ``--figure``, the joints' velocities of the first move and of its replan, joined.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dockjax import config
from dockjax.plan import Planner
from dockjax.plots import plot_joined
from dockjax.problem import DockingProblem

SPREAD = np.array([5.0, 5.0, 5.0, 0.1, 0.1, 1.0])
"""Half-widths of the random start and goal poses about the paper's (mm, °)."""


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--moves", type=int, default=10, help="random moves, each planned then replanned")
    ap.add_argument("--repeats", type=int, default=3, help="timings of each plan and replan (median kept)")
    ap.add_argument("--shift", type=float, default=0.3, help="how far the new goal moves along x [mm]")
    ap.add_argument("--at", type=float, default=1 / 3, help="replanning time as a fraction of T")
    ap.add_argument("--n-front", type=int, default=config.PLAN_FRONT, help="the planner's time caps")
    ap.add_argument("--rate", type=float, default=config.RATE, help="the planner's sampling rate [Hz]")
    ap.add_argument("--figure", default=None, help="write the joined velocities of the first move here")
    a = ap.parse_args(argv)
    if a.moves < 1 or a.repeats < 1 or not 0.0 <= a.at <= 1.0:
        ap.error("--moves and --repeats must be >= 1 and --at in [0, 1]")
    base = DockingProblem()
    planner = Planner(base, rate=a.rate, n_front=a.n_front)
    t0 = time.perf_counter()
    planner.warm()
    first_plan = planner.plan()
    planner.replan(first_plan, first_plan.T * a.at)  # compiles what replanning adds
    print(f"warm-up (template, compilation, one plan and one replan): {time.perf_counter() - t0:.1f} s")
    rng = np.random.default_rng(0)
    print("| move | plan [s] | replan [s] | replan / plan | jump: position | velocity | acceleration "
          "| T plan [s] | T replan [s] |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    ratios, rows, walls, joined = [], [], [], None
    for m in range(a.moves):
        start = np.asarray(base.start) + rng.uniform(-1, 1, 6) * SPREAD
        goal = np.asarray(base.goal) + rng.uniform(-1, 1, 6) * SPREAD
        times = []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            p = planner.plan(start, goal)
            t1 = time.perf_counter()
            q = planner.replan(p, p.T * a.at, goal=goal + [a.shift, 0, 0, 0, 0, 0])
            times.append((t1 - t0, time.perf_counter() - t1))
        t_plan, t_replan = np.median(times, axis=0)
        t = p.T * a.at
        grid = np.linspace(0.0, p.T, 2001)
        jumps = [np.abs(q.trajectory.pose([0.0], k)[0] - p.trajectory.pose([t], k)[0]).max()
                 / np.abs(p.trajectory.pose(grid, k)).max() for k in range(3)]
        ratios.append(t_replan / t_plan)
        walls.append((t_plan, t_replan))
        rows.append(jumps)
        print(f"| {m} | {t_plan:.2f} | {t_replan:.2f} | {t_replan / t_plan:.2f} | {jumps[0]:.1e} | {jumps[1]:.1e} "
              f"| {jumps[2]:.1e} | {p.T:.2f} | {q.T:.2f} |", flush=True)
        if joined is None:
            joined = (p, q, t)
    walls = np.array(walls)
    for name, w in zip(("plan", "replan"), walls.T):
        print(f"{name}: median {np.median(w):.2f} s, range {w.min():.2f}-{w.max():.2f} s")
    print(f"median replan / plan: {np.median(ratios):.2f} (range {min(ratios):.2f}-{max(ratios):.2f}); largest jumps: "
          + ", ".join(f"{v:.1e}" for v in np.max(rows, axis=0)))
    if a.figure:
        p, q, t = joined
        print(f"wrote {plot_joined(p.samples, q.samples, t, a.figure)}")


if __name__ == "__main__":
    main()
