"""One IMOCS run, 100 vmapped runs, and pymoo's NSGA-II on the same kernel.

    python benchmarks/bench_run.py [--pop 150] [--iters 100] [--runs 100] [--devices N] [--pymoo-runs 2]

Default docking problem, population 150, 100 iterations (15,150 evaluations per run).
Prints compile and run time of one IMOCS run and of ``--runs`` runs vmapped in one call,
the runs sharded over ``--devices`` CPU devices (default: one per usable core, as the sweep
CLI; one run shares the rows of each evaluation over them, and is also timed on one device
for comparison), the wall time of pymoo's NSGA-II with the same budget on the same kernel (via
``dockjax.interop``), the ratios, and the share of a run spent in evaluation.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dockjax import DockingProblem
from dockjax.algorithms import optimize


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pop", type=int, default=150)
    ap.add_argument("--iters", type=int, default=100)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--pymoo-runs", type=int, default=2)
    ap.add_argument("--devices", type=int, default=None, help="CPU devices (default: usable cores)")
    args = ap.parse_args()
    for name in ("pop", "iters", "runs"):
        if getattr(args, name) < (4 if name == "pop" else 1):
            ap.error(f"--{name} must be >= {4 if name == 'pop' else 1}, got {getattr(args, name)}")
    if args.pymoo_runs < 0:
        ap.error(f"--pymoo-runs must be >= 0, got {args.pymoo_runs}")
    from dockjax.cli import claim_devices

    try:
        devices = claim_devices(args.devices)  # before any JAX computation
    except ValueError as exc:
        ap.error(str(exc))
    problem = DockingProblem()

    t0 = time.perf_counter()
    optimize("imocs", problem, seeds=[0], pop_size=args.pop, n_iter=args.iters)
    first = time.perf_counter() - t0
    # medians over 5 seeds (this host is shared and noisy)
    one = float(np.median([optimize("imocs", problem, seeds=[s], pop_size=args.pop, n_iter=args.iters).seconds
                           for s in range(1, 6)]))
    print(f"IMOCS, 1 run on {devices} device(s): compile+run {first:.1f} s, run {one:.2f} s")
    if devices > 1:
        optimize("imocs", problem, seeds=[0], pop_size=args.pop, n_iter=args.iters, devices=1)
        solo = float(np.median([optimize("imocs", problem, seeds=[s], pop_size=args.pop, n_iter=args.iters,
                                         devices=1).seconds for s in range(1, 6)]))
        print(f"IMOCS, 1 run on 1 device: run {solo:.2f} s (rows shared over {devices} devices: {one / solo:.2f}x the time)")

    t0 = time.perf_counter()
    optimize("imocs", problem, seeds=range(args.runs), pop_size=args.pop, n_iter=args.iters)
    first_b = time.perf_counter() - t0
    batch = optimize("imocs", problem, seeds=range(args.runs, 2 * args.runs), pop_size=args.pop, n_iter=args.iters).seconds
    print(f"IMOCS, {args.runs} runs vmapped on {min(devices, args.runs)} device(s): compile+run {first_b:.1f} s, run {batch:.1f} s "
          f"({args.runs / batch:.2f} runs/s)")

    # evaluation share: the kernel alone on what a run scores — its own candidates (the
    # final population of the timed run; random candidates are dearer: more of them
    # overflow the screen) — called iters + 1 times inside one compiled loop, as in the
    # run (no per-call dispatch); each call depends on the last, so XLA cannot hoist it
    import jax

    X = optimize("imocs", problem, seeds=[1], pop_size=args.pop, n_iter=args.iters).X[0]
    with jax.enable_x64(True):
        def calls(X0):
            def body(_, Xi):
                F, G = problem.evaluate_jax(Xi)
                return Xi + 0.0 * (F[:, :1] + G[:, :1])
            return jax.lax.fori_loop(0, args.iters + 1, body, X0)

        loop = jax.jit(calls)
        Xj = jax.numpy.asarray(X)
        jax.block_until_ready(loop(Xj))
        runs = []
        for _ in range(5):
            t0 = time.perf_counter()
            jax.block_until_ready(loop(Xj))
            runs.append(time.perf_counter() - t0)
    eval_s = float(np.median(runs))
    print(f"evaluation alone (kernel on a run's {args.pop} candidates x {args.iters + 1}, one compiled loop): "
          f"{eval_s:.2f} s of the {one:.2f} s run ({100 * eval_s / one:.0f} %); the rest is ranking, "
          f"survival and variation")
    if args.pymoo_runs < 1:
        print("pymoo skipped (--pymoo-runs 0)")
        return

    from pymoo.algorithms.moo.nsga2 import NSGA2
    from pymoo.optimize import minimize

    from dockjax.interop import as_pymoo_problem

    pp = as_pymoo_problem(problem)
    problem.evaluate(X)  # compile pymoo's batch shape first: time runs, not compiles
    times = []
    for s in range(args.pymoo_runs):
        t0 = time.perf_counter()
        minimize(pp, NSGA2(pop_size=args.pop), ("n_gen", args.iters + 1), seed=s)
        times.append(time.perf_counter() - t0)
    py = float(np.median(times))
    print(f"pymoo NSGA-II on the dockjax kernel: {py:.2f} s per run (median of {args.pymoo_runs})")
    print(f"ratio, one run: {py / one:.1f}x (target >= 10x)")
    print(f"ratio, throughput of {args.runs} vmapped runs vs pymoo runs one after another: "
          f"{py * args.runs / batch:.1f}x (target >= 30x)")


if __name__ == "__main__":
    main()
