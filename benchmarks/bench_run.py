"""One IMOCS run, 100 vmapped runs, and pymoo's NSGA-II on the same kernel.

    python benchmarks/bench_run.py [--pop 150] [--iters 100] [--runs 100] [--devices N] [--pymoo-runs 5]
    python benchmarks/bench_run.py --pop 8 --iters 3 --runs 2 --pymoo-runs 1  # quick

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
from dockjax.optimize import optimize


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pop", type=int, default=150)
    ap.add_argument("--iters", type=int, default=100)
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--pymoo-runs", type=int, default=5,
                    help="pymoo runs, each interleaved with a timed IMOCS run (0: skip pymoo)")
    ap.add_argument("--devices", type=int, default=None, help="CPU devices (default: usable cores)")
    args = ap.parse_args(argv)
    for name in ("pop", "iters", "runs"):
        if getattr(args, name) < (4 if name == "pop" else 1):
            ap.error(f"--{name} must be >= {4 if name == 'pop' else 1}, got {getattr(args, name)}")
    if args.pymoo_runs < 0:
        ap.error(f"--pymoo-runs must be >= 0, got {args.pymoo_runs}")
    from dockjax.runtime import claim_devices

    try:
        devices = claim_devices(args.devices)  # before any JAX computation
    except ValueError as exc:
        ap.error(str(exc))
    problem = DockingProblem()
    run = lambda seeds, **kw: optimize("imocs", problem, seeds=seeds, pop_size=args.pop, n_iter=args.iters, **kw)  # noqa: E731

    t0 = time.perf_counter()
    run([0])
    first = time.perf_counter() - t0
    print(f"IMOCS, 1 run on {devices} device(s): compile+run {first:.1f} s")
    if devices > 1:
        run([0], devices=1)

    t0 = time.perf_counter()
    run(list(range(args.runs)))
    first_b = time.perf_counter() - t0
    batch = run(list(range(args.runs, 2 * args.runs))).seconds
    print(f"IMOCS, {args.runs} runs vmapped on {min(devices, args.runs)} device(s): compile+run {first_b:.1f} s, "
          f"run {batch:.1f} s ({args.runs / batch:.2f} runs/s)")

    # evaluation share: the kernel alone on what a run scores — its own candidates (the
    # final population of a run; random candidates are dearer: more of them overflow the
    # screen) — called iters + 1 times inside one compiled loop, as in the run (no per-call
    # dispatch); each call depends on the last, so XLA cannot hoist it
    import jax

    X = run([1], devices=1).X[0]
    with jax.enable_x64(True):
        def calls(X0):
            def body(_, Xi):
                F, G = problem.evaluate_jax(Xi)
                return Xi + 0.0 * (F[:, :1] + G[:, :1])
            return jax.lax.fori_loop(0, args.iters + 1, body, X0)

        loop = jax.jit(calls)
        Xj = jax.numpy.asarray(X)
        jax.block_until_ready(loop(Xj))
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            jax.block_until_ready(loop(Xj))
            times.append(time.perf_counter() - t0)
    eval_s = float(np.median(times))

    n_pymoo, why_not = args.pymoo_runs, "--pymoo-runs 0"
    if n_pymoo:
        try:
            from pymoo.algorithms.moo.nsga2 import NSGA2
            from pymoo.optimize import minimize
        except ImportError as exc:
            n_pymoo, why_not = 0, f"pymoo is not importable ({exc}); pip install 'dockjax[bench]'"
    if n_pymoo:
        from dockjax.interop import as_pymoo_problem

        pp = as_pymoo_problem(problem)
        problem.evaluate(X)  # compile pymoo's batch shape first: time runs, not compiles

        def pymoo_run(seed):
            t0 = time.perf_counter()
            minimize(pp, NSGA2(pop_size=args.pop), ("n_gen", args.iters + 1), seed=seed)
            return time.perf_counter() - t0

    # one run: rounds of (IMOCS on the default devices, on one device, pymoo), interleaved
    # so that the host's slow and fast spells fall on all of them; medians
    rounds = max(n_pymoo, 5)
    ones, solos, pys = [], [], []
    for r in range(rounds):
        ones.append(run([r + 1]).seconds)
        if devices > 1:
            solos.append(run([r + 1], devices=1).seconds)
        if r < n_pymoo:
            pys.append(pymoo_run(r))
    one = float(np.median(ones))
    solo = float(np.median(solos)) if solos else one
    print(f"IMOCS, 1 run on {devices} device(s): run {one:.3f} s (median of {rounds})")
    if devices > 1:
        ratios = np.array(ones) / np.array(solos)
        print(f"IMOCS, 1 run on 1 device: run {solo:.3f} s; rows shared over {devices} devices: "
              f"{np.median(ratios):.2f}x the time (median of {rounds} interleaved pairs)")
    print(f"evaluation alone (kernel on a run's {args.pop} candidates x {args.iters + 1}, one compiled loop, "
          f"one device): {eval_s:.3f} s of the {solo:.3f} s one-device run ({100 * eval_s / solo:.0f} %); "
          f"the rest is ranking, survival and variation")
    if not pys:
        print(f"pymoo NSGA-II skipped: {why_not}")
        return
    py = float(np.median(pys))
    pairs = np.array(pys) / np.array(ones[: len(pys)])
    print(f"pymoo NSGA-II on the dockjax kernel: {py:.2f} s per run (median of {len(pys)}, "
          f"{', '.join(f'{t:.2f}' for t in pys)})")
    print(f"ratio, one run: {py / one:.1f}x (median of the {len(pys)} interleaved pairs: {np.median(pairs):.1f}x)")
    print(f"ratio, throughput of {args.runs} vmapped runs vs pymoo runs one after another: "
          f"{py * args.runs / batch:.1f}x")


if __name__ == "__main__":
    main()
