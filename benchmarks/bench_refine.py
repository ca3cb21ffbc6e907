"""Gradient refinement and the best-known front, in one process.

    python benchmarks/bench_refine.py [--steps 200] [--repeats 3]

1. The best-known front of the default problem (``dockjax.config.BEST_KNOWN`` settings),
   wall time with compile included (it runs first, on a cold process).
2. Refining the final population (150 points) of one IMOCS run (population 150,
   100 iterations): median wall time over ``--repeats`` after compile (same compiled shape
   as step 1), and the hypervolume of the front before and after.
3. The hypervolume of the best-known front beside them (reference point of
   ``dockjax.best_known.reference_point``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dockjax.best_known import best_known_cached, reference_point
from dockjax.config import BEST_KNOWN
from dockjax.metrics import hypervolume_numpy
from dockjax.optimize import optimize
from dockjax.problem import make_problem
from dockjax.refine import refine


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200, help="refinement steps (default 200, refine's default)")
    ap.add_argument("--repeats", type=int, default=3, help="timed repeats after compile")
    a = ap.parse_args(argv)
    problem = make_problem("paper")
    ref = reference_point(problem)

    t0 = time.perf_counter()
    front = best_known_cached(problem, None, log=lambda m: None)
    t_best = time.perf_counter() - t0
    print(f"best-known front ({BEST_KNOWN}): {len(front.F)} points, {t_best:.1f} s wall, compile included")

    r = optimize("imocs", problem, seeds=[0], pop_size=150, n_iter=100)
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
