"""Compile and run time of dockjax's main programs under XLA:CPU's two code generators.

    python benchmarks/bench_compile.py [--pairs 5] [--programs evaluate optimize taylor] [--rows 1024]
    python benchmarks/bench_compile.py --pairs 1 --programs evaluate --rows 16  # quick

XLA:CPU emits its fused loops either with its default (MLIR) fusion emitters or with the
classic ones (``--xla_cpu_use_fusion_emitters=false``). Each measurement is a fresh Python
process (the flag is read when JAX starts; no persistent compilation cache), the two
generators alternating pair by pair so that the machine's load falls on both alike. Per
program: seconds of XLA compilation (JAX's ``backend_compile`` events) and the median
run time of ``--repeats`` calls after the first, then the ratios classic / default (medians
over the pairs), and the largest relative difference of the results between generators.

Programs: ``evaluate`` (:meth:`dockjax.DockingProblem.evaluate` of the paper's problem,
screened, ``--rows`` random candidates), ``optimize`` (IMOCS on the paper's problem, 2 seeds,
population 16, 10 iterations, the scan driver), ``taylor`` (``evaluate`` with the right arm's
Taylor models, 16 candidates).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

PROGRAMS = ("evaluate", "optimize", "taylor")
CLASSIC = "--xla_cpu_use_fusion_emitters=false"

CHILD = r"""
import json, sys, time
import jax.monitoring
compiled = [0.0]
def count(event, seconds, **_):
    if event.endswith("backend_compile_duration"):
        compiled[0] += seconds
jax.monitoring.register_event_duration_secs_listener(count)
import numpy as np
from dockjax import DockingProblem
from dockjax.optimize import optimize

programs, rows, repeats = sys.argv[1].split(","), int(sys.argv[2]), int(sys.argv[3])
problem = DockingProblem()
X = np.random.default_rng(0).uniform(problem.lower, problem.upper, (rows, problem.n_var))
calls = {
    "evaluate": lambda: np.concatenate(problem.evaluate(X), 1),
    "optimize": lambda: optimize("imocs", problem, seeds=[0, 1], pop_size=16, n_iter=10).F,
    "taylor": lambda: np.concatenate(problem.with_right_arm("taylor").evaluate(X[:16]), 1),
}
out = {}
for name in programs:
    before = compiled[0]
    result = calls[name]()
    compile_s = compiled[0] - before
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        calls[name]()
        times.append(time.perf_counter() - t)
    out[name] = {"compile_s": compile_s, "run_s": float(np.median(times)), "result": np.asarray(result).tolist()}
print(json.dumps(out))
"""


def _flags(classic: bool) -> str:
    flags = os.environ.get("XLA_FLAGS", "").replace(CLASSIC, "")
    return (flags + " " + CLASSIC).strip() if classic else flags.strip()


def _measure(classic: bool, programs: list[str], rows: int, repeats: int) -> dict:
    env = {**os.environ, "XLA_FLAGS": _flags(classic)}
    r = subprocess.run([sys.executable, "-c", CHILD, ",".join(programs), str(rows), str(repeats)], env=env,
                       capture_output=True, text=True, timeout=1800)
    if r.returncode != 0:
        raise RuntimeError(f"the measuring process failed:\n{r.stderr[-2000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pairs", type=int, default=5, help="processes per code generator (alternating)")
    ap.add_argument("--programs", nargs="+", default=list(PROGRAMS), choices=PROGRAMS, metavar="NAME",
                    help=f"programs to compile (default all: {', '.join(PROGRAMS)})")
    ap.add_argument("--rows", type=int, default=1024, help="candidates of the evaluate program")
    ap.add_argument("--repeats", type=int, default=5, help="timed calls after the first")
    args = ap.parse_args(argv)
    if args.pairs < 1 or args.rows < 1 or args.repeats < 1:
        ap.error("--pairs, --rows and --repeats must be >= 1")
    runs = {False: [], True: []}
    for i in range(args.pairs):
        for classic in ((False, True) if i % 2 == 0 else (True, False)):
            runs[classic].append(_measure(classic, args.programs, args.rows, args.repeats))
    print(f"medians of {args.pairs} fresh process(es) per code generator; run time: median of {args.repeats} calls")
    print(f"{'program':>9} {'compile default':>15} {'classic':>8} {'ratio':>6} {'run default':>12} {'classic':>8} "
          f"{'ratio':>6} {'result rel. diff':>16}")
    for name in args.programs:
        med = {c: {k: float(np.median([r[name][k] for r in runs[c]])) for k in ("compile_s", "run_s")}
               for c in runs}
        ratio = {k: float(np.median([b[name][k] / a[name][k] for a, b in zip(runs[False], runs[True])]))
                 for k in ("compile_s", "run_s")}
        a, b = np.asarray(runs[False][0][name]["result"]), np.asarray(runs[True][0][name]["result"])
        diff = float(np.max(np.abs(a - b) / np.maximum(np.abs(a), 1e-300)))
        print(f"{name:>9} {med[False]['compile_s']:>14.2f}s {med[True]['compile_s']:>7.2f}s {ratio['compile_s']:>6.2f} "
              f"{1e3 * med[False]['run_s']:>10.1f}ms {1e3 * med[True]['run_s']:>6.1f}ms {ratio['run_s']:>6.2f} "
              f"{diff:>16.1e}")


if __name__ == "__main__":
    main()
