"""Staged moves: the documented three-stage docking, passing its alignment via at speed against stopping there.

    python benchmarks/bench_stages.py [--move docs/docking.toml] [--interval-bounds 0.5 10] [--figure staged.png]
    python benchmarks/bench_stages.py --rate 20 --select time --calls 1 --no-peer --figure staged.png  # quick

The move of ``--move`` (start, goal and vias; docs/docking.toml: approach, alignment
through a via passed with continuous velocity, insertion at a tenth of the limits after a
stop) is planned by :func:`dockjax.stages.plan_staged` for the shortest time and for Eq.
26's compromise, and so is the same move with a stop at every via (the peer: stage by
stage, each from rest to rest). Printed per plan: T (s, dwells included), the jerk of the
whole motion, each stage's duration, and the wall time of a first and a second call in
this process (the first compiles or loads the programmes; ``--calls 1``: the first only). With ``--figure``, the
shortest-time staged plan's joints against their stages' limits.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

from dockjax import config
from dockjax.plots import plot_joints
from dockjax.stages import load_move_problem, plan_staged


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--move", default=str(Path(__file__).resolve().parents[1] / "docs" / "docking.toml"),
                    help="the move file (default docs/docking.toml)")
    ap.add_argument("--interval-bounds", type=float, nargs=2, default=[0.5, 10.0], help="knot interval bounds [s]")
    ap.add_argument("--rate", type=float, default=100.0, help="sampling rate of the certificate [Hz]")
    ap.add_argument("--n-front", type=int, default=config.PLAN_FRONT, help="time caps of the compromise's front")
    ap.add_argument("--select", nargs="+", choices=("time", "compromise"), default=["time", "compromise"],
                    help="which plans: the shortest time (weights 1 0), the compromise (weights 1 1)")
    ap.add_argument("--peer", action=argparse.BooleanOptionalAction, default=True,
                    help="also plan the move with a stop at every via")
    ap.add_argument("--calls", type=int, choices=(1, 2), default=2, help="timed calls per plan")
    ap.add_argument("--figure", default=None, help="write the shortest-time staged plan's joints here")
    a = ap.parse_args(argv)
    problem, vias = load_move_problem(a.move, interval_bounds=tuple(a.interval_bounds))
    stops = tuple(dataclasses.replace(v, stop=True) for v in vias)
    print("| plan | weights | T [s] | jerk | stages [s] | first call [s] | second call [s] |")
    print("|---|---|---:|---:|---|---:|---:|")
    shortest = None
    plans = [("passing the vias marked stop = false", vias)]
    plans += [("stopping at every via (peer)", stops)] if a.peer else []
    for label, vv in plans:
        for weights in [{"time": (1.0, 0.0), "compromise": (1.0, 1.0)}[k] for k in a.select]:
            walls = []
            for _ in range(a.calls):
                t0 = time.perf_counter()
                sp = plan_staged(problem, vv, weights=weights, rate=a.rate, n_front=a.n_front)
                walls.append(time.perf_counter() - t0)
            stages = ", ".join(f"{s.T:.3f}" for s in sp.stages)
            second = f"{walls[1]:.1f}" if len(walls) > 1 else "-"
            print(f"| {label} | {weights} | {sp.T:.3f} | {sp.jerk:.4g} | {stages} | {walls[0]:.1f} | {second} |",
                  flush=True)
            if shortest is None and weights[1] == 0:
                shortest = sp
    if a.figure and shortest is not None:
        path = plot_joints(shortest.sample(), shortest.sample_limits(), a.figure, home=shortest.stages[0].problem.home,
                           title=f"staged docking, shortest time T = {shortest.T:.2f} s (limits: each stage's)")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
