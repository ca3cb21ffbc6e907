"""Throughput of a sweep chunk, the extrapolated wall time of a 1000-run sweep, and pymoo.

    python benchmarks/bench_sweep.py [--pop 150] [--iters 100] [--chunk 40] [--runs 1000]
                                     [--devices N] [--rounds 3] [--pymoo-runs 2]
    python benchmarks/bench_sweep.py --pop 8 --iters 3 --chunk 2 --rounds 1 --pymoo-runs 1  # quick

Times :func:`dockjax.sweep.run_chunk` (one compiled vmapped IMOCS call over ``--chunk`` runs,
each with its own seed, ρ and α_max, plus the indicators of every run against the front of
a pilot chunk at IMOCS's defaults, as a sweep's reference pilot) with the runs sharded over
``--devices`` CPU devices (default: one per usable core, as the sweep CLI), and, as the
peer in the same process, on one device (XLA's intra-op threads only): the first call of
each (compile + run), then ``--rounds`` interleaved rounds of one call each; medians are
quoted, and the compile time is the pilot's first call less a chunk's run. Extrapolates the
wall time of a sweep of ``--runs`` runs in chunks of that size (one compilation +
ceil(runs / chunk) chunks, in process, no chunk-file I/O which is milliseconds). Then times
pymoo's NSGA-II with the same budget (population ``--pop``, ``--iters`` + 1 generations) on
the same compiled kernel (via :func:`dockjax.interop.as_pymoo_problem`) for
``--pymoo-runs`` runs, and prints the ratio of pymoo's time per run to the sweep's time per
run.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from dockjax import config
from dockjax.metrics import nondominated_points
from dockjax.sweep import ChunkSpec, run_chunk


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pop", type=int, default=150)
    ap.add_argument("--iters", type=int, default=100)
    ap.add_argument("--chunk", type=int, default=40, help="runs per compiled call")
    ap.add_argument("--runs", type=int, default=1000, help="sweep size to extrapolate to")
    ap.add_argument("--pymoo-runs", type=int, default=2)
    ap.add_argument("--preset", default="paper", choices=("paper", "wide"))
    ap.add_argument("--devices", type=int, default=None, help="CPU devices (default: usable cores)")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved timed rounds")
    args = ap.parse_args(argv)
    from dockjax.runtime import claim_devices

    try:
        devices = claim_devices(args.devices)  # before any JAX computation
    except ValueError as exc:
        ap.error(str(exc))

    n = args.chunk
    rng = np.random.default_rng(0)

    def spec(offset: int, defaults: bool = False) -> ChunkSpec:
        """A chunk of ``n`` runs, seeds from ``offset``, each with its own ρ and α_max drawn
        from the sweep's grid (``defaults``: IMOCS's defaults, as a sweep's pilot)."""
        rho = rng.choice(config.SWEEP_RHO, n).tolist()
        alpha_max = rng.choice(config.SWEEP_ALPHA_MAX, n).tolist()
        hyper = ((),) * n if defaults else tuple((("rho", r), ("alpha_max", a)) for r, a in zip(rho, alpha_max))
        return ChunkSpec(round=0, index=0, preset=args.preset, algorithm="imocs", pop=args.pop, iters=args.iters,
                         settings=tuple(range(n)), seeds=tuple(range(offset, offset + n)), hyper=hyper, n_real=n)

    t0 = time.perf_counter()
    pilot = run_chunk(spec(10_000, defaults=True), devices=devices)  # compiles; the indicators' reference front
    pilot_s = time.perf_counter() - t0
    front = nondominated_points(pilot["front_F"])
    ref = {"front": front, "ideal": front.min(0), "nadir": front.max(0), "hv_ref": config.HV_REFERENCE}
    layouts = {"one device": 1, f"{devices} devices": devices} if devices > 1 else {"one device": 1}
    times = {k: [] for k in layouts}
    for d in layouts.values():  # compile every layout (and the indicators) before timing
        run_chunk(spec(20_000), ref, devices=d)
    for k in range(args.rounds):
        for name, d in layouts.items():
            t0 = time.perf_counter()
            run_chunk(spec(k * n), ref, devices=d)
            times[name].append(time.perf_counter() - t0)
    chunks = math.ceil(args.runs / n)
    compile_s = max(pilot_s - float(np.median(times[list(layouts)[-1]])), 0.0)
    print(f"IMOCS pop {args.pop}, {args.iters} iterations, chunks of {n} runs ({args.preset} preset), "
          f"median of {args.rounds} interleaved rounds; compile ~{compile_s:.1f} s")
    for name in layouts:
        chunk_s = float(np.median(times[name]))
        total = compile_s + chunks * chunk_s
        print(f"  {name}: one chunk {chunk_s:.2f} s = {chunk_s / n:.3f} s per run, {n / chunk_s:.2f} runs/s; "
              f"{args.runs} runs: {chunks} chunks + compile = {total:.0f} s ({total / 60:.1f} min)")
    best = min(layouts, key=lambda k: np.median(times[k]))
    if len(layouts) > 1:
        print(f"  {best} fastest: {np.median(times['one device']) / np.median(times[best]):.2f}x one device")
    per_run = float(np.median(times[best])) / n

    if args.pymoo_runs > 0:
        try:
            from pymoo.algorithms.moo.nsga2 import NSGA2
            from pymoo.optimize import minimize
        except ImportError as exc:
            print(f"pymoo NSGA-II skipped: pymoo is not importable ({exc}); pip install 'dockjax[bench]'")
            return
        from dockjax.interop import as_pymoo_problem
        from dockjax.problem import make_problem

        pp = as_pymoo_problem(make_problem(args.preset))
        pp.evaluate(np.tile(pp.xl, (args.pop, 1)))  # compile the kernel for this shape
        py = []
        for s in range(args.pymoo_runs):
            t0 = time.perf_counter()
            minimize(pp, NSGA2(pop_size=args.pop), ("n_gen", args.iters + 1), seed=s)
            py.append(time.perf_counter() - t0)
        py_run = float(np.median(py))
        print(f"pymoo NSGA-II, same budget, same kernel: {py_run:.2f} s per run (median of {args.pymoo_runs}); "
              f"{args.runs} runs one after another: {py_run * args.runs / 60:.1f} min")
        print(f"  ratio pymoo per run / sweep per run: {py_run / per_run:.1f}x")


if __name__ == "__main__":
    main()
