"""Cabins on more than two supports: plans and scoring cost against the paper's two arms.

    python benchmarks/bench_supports.py [--rows 1024] [--repeats 5] [--n-front 8] [--rate 1000]
    python benchmarks/bench_supports.py --rows 16 --repeats 1 --n-front 2 --rate 20 --cabins 2  # quick

The default move on the cabins of :data:`CABINS` (``--cabins``: the first that many): the
paper's two arms; three supports at 0, 1000 and 2000 mm with the paper's limits; the same
with the middle support's lateral joint limited to 1.2 mm/s; four supports at 0, 700,
1400 and 2000 mm. Per cabin, printed as one table: the right-arm treatment ``"auto"``
chose, the shortest-time plan and the compromise plan of :func:`dockjax.plan.plan` (T,
jerk, the binding limits, each plan's wall time: the median of ``--repeats`` after one
untimed run), and the scoring time of ``--rows`` random candidates of the decision box with every span through
the root chain (``evaluate(screen=False)``, the only path of a cabin on more supports),
the median of ``--repeats``, as a ratio to the two arms' in the same run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dockjax import config
from dockjax.plan import plan
from dockjax.problem import DockingProblem

SLOW_MIDDLE = [400, 25, 2.5, 6.8, 400, 25, 1.2, 6.8, 400, 25, 2.5, 6.8]
CABINS = (
    ("two arms (0, 2000)", {}),
    ("three (0, 1000, 2000)", {"supports": (0, 1000, 2000)}),
    ("three, middle lateral 1.2 mm/s", {"supports": (0, 1000, 2000), "velocity": SLOW_MIDDLE}),
    ("four (0, 700, 1400, 2000)", {"supports": (0, 700, 1400, 2000)}),
)


def _timed(f, repeats: int):
    """(result, median wall time of ``repeats`` calls after one untimed call)."""
    out, times = f(), []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return out, float(np.median(times))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1024, help="candidates scored per timing")
    ap.add_argument("--repeats", type=int, default=5, help="timings of the scoring (median)")
    ap.add_argument("--n-front", type=int, default=config.PLAN_FRONT, help="time caps of the compromise plan")
    ap.add_argument("--rate", type=float, default=config.RATE, help="the plans' sampling rate [Hz]")
    ap.add_argument("--cabins", type=int, default=len(CABINS), help="how many of the cabins (in order)")
    a = ap.parse_args(argv)
    if a.rows < 1 or a.repeats < 1 or not 1 <= a.cabins <= len(CABINS):
        ap.error(f"--rows and --repeats must be >= 1, --cabins in 1..{len(CABINS)}")
    print("| cabin | treatment | shortest T [s] | binding | jerk of the compromise | its T [s] "
          "| plan [s]: shortest, compromise | scoring / two arms' |")
    print("|---|---|---:|---|---:|---:|---:|---:|")
    base = None
    for name, kw in CABINS[: a.cabins]:
        problem = DockingProblem(**kw)
        rng = np.random.default_rng(0)
        X = problem.lower + rng.random((a.rows, problem.n_var)) * (problem.upper - problem.lower)
        times = []
        for _ in range(1 + a.repeats):  # the first compiles
            t0 = time.perf_counter()
            problem.evaluate(X, screen=False)
            times.append(time.perf_counter() - t0)
        score = float(np.median(times[1:]))
        base = score if base is None else base
        fast, t_fast = _timed(lambda p=problem: plan(p, weights=(1, 0), rate=a.rate, n_front=a.n_front,
                                                     check_sensitivities=False), a.repeats)
        comp, t_comp = _timed(lambda p=problem: plan(p, weights=(1, 1), rate=a.rate, n_front=a.n_front,
                                                     check_sensitivities=False), a.repeats)
        binding = ", ".join(b["limit"] for b in fast.explanation["binding"]) or "none"
        print(f"| {name} | {problem.right_arm} | {fast.T:.3f} | {binding} | {comp.jerk:.4f} | {comp.T:.3f} "
              f"| {t_fast:.2f}, {t_comp:.2f} | {score / base:.2f} |", flush=True)


if __name__ == "__main__":
    main()
