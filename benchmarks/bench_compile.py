"""Compile and run time of dockjax's main programs under two sets of XLA:CPU flags.

    python benchmarks/bench_compile.py [--pairs 5] [--programs evaluate optimize nsga2 taylor] [--rows 1024]
                                       [--a FLAGS] [--b FLAGS]
    python benchmarks/bench_compile.py --pairs 1 --programs evaluate --rows 16  # quick

Side A compiles with ``--a`` added to ``XLA_FLAGS`` (default none: JAX's defaults), side B
with ``--b`` (default ``--xla_cpu_use_fusion_emitters=false``: XLA:CPU's classic fusion
emitters instead of its default MLIR ones). With
``--a=--xla_cpu_use_fusion_emitters=false --b="--xla_cpu_use_fusion_emitters=false
--xla_backend_optimization_level=2"`` it measures LLVM optimisation level 2 against the
default (3), both with the classic emitters: the test suite's settings (``tests/conftest.py``).
Each measurement is a fresh Python process (flags are read when JAX starts; no persistent
compilation cache, dockjax's store of programs off), the two sides alternating pair by
pair so that the machine's load falls on both alike. Per program: seconds of XLA
compilation (JAX's ``backend_compile`` events) and the median run time of ``--repeats``
calls after the first, then the ratios B / A (medians over the pairs), and the largest
relative difference of the results between the sides.

Programs: ``evaluate`` (:meth:`dockjax.DockingProblem.evaluate` of the paper's problem,
screened, ``--rows`` random candidates), ``optimize`` (IMOCS on the paper's problem, 2 seeds,
population 16, 10 iterations, the scan driver), ``nsga2`` (NSGA-II on ZDT1, 30 variables, 5
seeds, population 100, 100 generations: one batched program), ``taylor`` (``evaluate`` with
the right arm's Taylor models, 16 candidates).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

PROGRAMS = ("evaluate", "optimize", "nsga2", "taylor")
CLASSIC = "--xla_cpu_use_fusion_emitters=false"
MANAGED = (CLASSIC, "--xla_backend_optimization_level")
"""Flags of the sides: removed from the inherited ``XLA_FLAGS`` before a side's own are added."""

CHILD = r"""
import json, sys, time
import jax.monitoring
compiled = [0.0]
def count(event, seconds, **_):
    if event.endswith("backend_compile_duration"):
        compiled[0] += seconds
jax.monitoring.register_event_duration_secs_listener(count)
import numpy as np
import jax
from dockjax import DockingProblem
from dockjax.algorithms import base, nsga2
from dockjax.algorithms.zdt import ZDT1
from dockjax.optimize import optimize

programs, rows, repeats = sys.argv[1].split(","), int(sys.argv[2]), int(sys.argv[3])
problem = DockingProblem()
X = np.random.default_rng(0).uniform(problem.lower, problem.upper, (rows, problem.n_var))
calls = {
    "evaluate": lambda: np.concatenate(problem.evaluate(X), 1),
    "optimize": lambda: optimize("imocs", problem, seeds=[0, 1], pop_size=16, n_iter=10).F,
    "taylor": lambda: np.concatenate(problem.with_right_arm("taylor").evaluate(X[:16]), 1),
}
nsga2_run = jax.jit(jax.vmap(lambda k: base.run(nsga2.ALGORITHM, k, ZDT1(), nsga2.Params(pop_size=100), 100)[0]))
def _nsga2():
    with jax.enable_x64(True):
        return np.asarray(nsga2_run(jax.vmap(jax.random.key)(np.arange(5))).pop.F)
calls["nsga2"] = _nsga2
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


def _flags(extra: str) -> str:
    """The inherited ``XLA_FLAGS`` without the flags of :data:`MANAGED`, plus ``extra``."""
    kept = [f for f in os.environ.get("XLA_FLAGS", "").split() if not f.startswith(MANAGED)]
    return " ".join(kept + extra.split())


def _measure(extra: str, programs: list[str], rows: int, repeats: int) -> dict:
    env = {**os.environ, "XLA_FLAGS": _flags(extra), "DOCKJAX_PROGRAMS": "off"}  # compiled, not loaded
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
    ap.add_argument("--a", default="", metavar="FLAGS", help="XLA flags of side A (default: none, JAX's defaults)")
    ap.add_argument("--b", default=CLASSIC, metavar="FLAGS", help=f"XLA flags of side B (default: {CLASSIC})")
    args = ap.parse_args(argv)
    if args.pairs < 1 or args.rows < 1 or args.repeats < 1:
        ap.error("--pairs, --rows and --repeats must be >= 1")
    for side in (args.a, args.b):
        if any(not f.startswith("--xla_") for f in side.split()):
            ap.error(f"--a and --b take XLA flags (each starting with --xla_), got {side!r}")
    runs = {False: [], True: []}
    for i in range(args.pairs):
        for b in ((False, True) if i % 2 == 0 else (True, False)):
            runs[b].append(_measure(args.b if b else args.a, args.programs, args.rows, args.repeats))
    print(f"A: {args.a or '(no flags)'}\nB: {args.b or '(no flags)'}")
    print(f"medians of {args.pairs} fresh process(es) per side; run time: median of {args.repeats} calls")
    print(f"{'program':>9} {'compile A':>15} {'B':>8} {'ratio':>6} {'run A':>12} {'B':>8} "
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
