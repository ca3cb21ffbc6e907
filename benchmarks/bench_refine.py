"""Gradient refinement and the best-known front, in one process.

    python benchmarks/bench_refine.py [--steps 200] [--repeats 3] [--pop 150] [--iters 100]
                                      [--best-known 150 20 600] [--presets paper wide]
                                      [--anchors 60 0 --anchors 200 3]
    python benchmarks/bench_refine.py --pop 8 --iters 3 --best-known 4 2 20 --presets paper --anchors 5 0  # quick

1. The best-known front of each preset (``--best-known`` its time caps, SQP anchors and
   refinement steps; default ``dockjax.config.BEST_KNOWN``) with each ``--anchors``
   setting (the anchors' SLSQP iterations and restarts; the first is
   ``best_known_front``'s default, the second fully converged anchors): the first call's
   wall time (compilation or loading from the store included; it runs first, on a cold
   process), the median of ``--repeats`` later calls, and the front's hypervolume
   (reference point of ``dockjax.best_known.reference_point``) against the first
   setting's.
2. Refining the final population (``--pop`` points) of one IMOCS run (population
   ``--pop``, ``--iters`` iterations): median wall time over ``--repeats`` after compile
   (same compiled shape as step 1 when the population and the front's time caps fall in
   one bucket of rows, as at the defaults), and the hypervolume of the front before and
   after.
3. The hypervolume of the paper preset's best-known front (first ``--anchors`` setting)
   beside them.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dockjax.best_known import best_known_front, reference_point
from dockjax.config import BEST_KNOWN
from dockjax.metrics import hypervolume_numpy
from dockjax.optimize import optimize
from dockjax.problem import make_problem
from dockjax.refine import refine


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200, help="refinement steps (default 200, refine's default)")
    ap.add_argument("--repeats", type=int, default=3, help="timed repeats after compile")
    ap.add_argument("--pop", type=int, default=150, help="IMOCS population (the points refined)")
    ap.add_argument("--iters", type=int, default=100, help="IMOCS iterations")
    ap.add_argument("--best-known", type=int, nargs=3, metavar=("POINTS", "ANCHORS", "STEPS"),
                    default=[BEST_KNOWN["n_points"], BEST_KNOWN["n_exact"], BEST_KNOWN["steps"]],
                    help="the best-known front's time caps, SQP anchors and refinement steps per cap "
                         "(default dockjax.config.BEST_KNOWN)")
    ap.add_argument("--presets", nargs="+", choices=("paper", "wide"), default=["paper", "wide"])
    ap.add_argument("--anchors", type=int, nargs=2, action="append", metavar=("ITER", "RESTARTS"),
                    help="SLSQP iterations and restarts of the anchors (repeatable; default 60 0 and 200 3)")
    a = ap.parse_args(argv)
    if a.repeats < 1:
        ap.error(f"--repeats must be >= 1, got {a.repeats}")
    anchors = a.anchors or [[60, 0], [200, 3]]
    settings = dict(zip(("n_points", "n_exact", "steps"), a.best_known))

    print(f"best-known front, {settings}; wall times: first call (compile or store load included), "
          f"median of {a.repeats} later calls")
    print("| preset | anchors (iterations, restarts) | first call [s] | later calls [s] | points | HV | HV / first |")
    print("|---|---|---:|---:|---:|---:|---:|")
    fronts = {}
    for preset in a.presets:
        hv0 = None
        for it, rs in anchors:
            problem = make_problem(preset)
            times = []
            for _ in range(1 + a.repeats):
                t0 = time.perf_counter()
                front = best_known_front(problem, anchor_iter=it, anchor_restarts=rs, **settings)
                times.append(time.perf_counter() - t0)
            hv = hypervolume_numpy(front.F, reference_point(problem))
            hv0 = hv if hv0 is None else hv0
            fronts.setdefault(preset, front)
            print(f"| {preset} | {it}, {rs} | {times[0]:.1f} | {np.median(times[1:]):.2f} | {len(front.F)} | "
                  f"{hv:.6f} | {hv / hv0:.7f} |", flush=True)

    problem = make_problem("paper")
    ref = reference_point(problem)
    front = fronts.get("paper") or best_known_front(problem, anchor_iter=anchors[0][0],
                                                    anchor_restarts=anchors[0][1], **settings)

    r = optimize("imocs", problem, seeds=[0], pop_size=a.pop, n_iter=a.iters)
    X = r.X[0]
    times = []
    for _ in range(a.repeats):
        t0 = time.perf_counter()
        out = refine(problem, X, steps=a.steps)
        times.append(time.perf_counter() - t0)
    before = r.F[0][r.front[0]]
    after = np.vstack([out.F[out.feasible], before])
    hv_b, hv_a, hv_k = (hypervolume_numpy(F, ref) for F in (before, after, front.F))
    print(f"refine {len(X)} points x {a.steps} steps: median {np.median(times):.2f} s after compile "
          f"(runs {', '.join(f'{t:.2f}' for t in times)}); {out.improved.sum()} improved, "
          f"{out.feasible.sum()} feasible")
    print(f"hypervolume (ref point {np.round(ref, 3).tolist()}): IMOCS front {hv_b:.3f}, refined {hv_a:.3f}, "
          f"best-known {hv_k:.3f}; IMOCS at {100 * hv_b / hv_k:.2f} %, refined at {100 * hv_a / hv_k:.2f} % "
          f"of the best-known")


if __name__ == "__main__":
    main()
