"""The first call in a new Python process against a warm call, with dockjax's store of
compiled programs (:mod:`dockjax.store`) and with JAX's persistent compilation cache.

python benchmarks/bench_fresh.py [--pairs 3] [--calls evaluate plan planner] [--rows 100]
                                 [--settings cold store jax-cache]
python benchmarks/bench_fresh.py --pairs 1 --calls evaluate --rows 16 --settings cold store  # quick

Every measurement is a new Python process that imports dockjax, makes one call twice and
reports the import time, the first call's time and the second's (warm). Calls: ``evaluate``
(:meth:`dockjax.DockingProblem.evaluate` of ``--rows`` random candidates of the paper's
problem), ``plan`` (:func:`dockjax.plan.plan` of the paper's default move, the second call
on the same move) and ``planner`` (a :class:`dockjax.plan.Planner`'s first ``plan`` of a
start 1 mm off the default one in x, y and z, which first loads or solves the template,
then the same move again: the warm call solves the same programmes from the same starts).

Per pair of measurements, in new folders: ``cold`` (an empty store, as a first run with
the library's defaults: everything compiles, and the store fills), then ``store`` (the
store it filled); and, for comparison, ``jax-cache``: the store off and JAX's persistent
cache (:func:`dockjax.enable_compilation_cache`) filled by one unreported run before. The
table gives, per call and setting, the medians over the pairs of the first call, the warm
call and their difference (the cost of a new process beyond the import), and the import
time.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CALLS = ("evaluate", "plan", "planner")
SETTINGS = ("cold", "store", "jax-cache")

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import numpy as np
import dockjax
from dockjax import DockingProblem
from dockjax.plan import Planner, plan
t1 = time.perf_counter()
call, rows, jax_cache = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
if jax_cache:
    dockjax.enable_compilation_cache()
problem = DockingProblem()
if call == "evaluate":
    X = np.random.default_rng(0).uniform(problem.lower, problem.upper, (rows, problem.n_var))
    first = second = lambda: problem.evaluate(X)
elif call == "plan":
    first = second = lambda: plan(problem)
else:
    planner = Planner(problem)
    move = np.asarray(problem.start) + np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    first = second = lambda: planner.plan(move)
times = []
for f in (first, second):
    t = time.perf_counter()
    f()
    times.append(time.perf_counter() - t)
print(json.dumps({"import": t1 - t0, "first": times[0], "warm": times[1]}))
"""


def _measure(call: str, rows: int, setting: str, store: Path, cache: Path) -> dict:
    """One new process: the store on (``cold``, ``store``) or JAX's cache (``jax-cache``)."""
    env = dict(os.environ)
    env["DOCKJAX_PROGRAMS"] = "off" if setting == "jax-cache" else str(store)
    env["DOCKJAX_CACHE"] = str(cache)
    r = subprocess.run([sys.executable, "-c", CHILD, call, str(rows), "1" if setting == "jax-cache" else "0"],
                       env=env, capture_output=True, text=True, timeout=1800)
    if r.returncode != 0:
        raise SystemExit(f"{call} ({setting}) failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=3, help="measurements per call and setting (medians)")
    ap.add_argument("--calls", nargs="+", choices=CALLS, default=list(CALLS))
    ap.add_argument("--rows", type=int, default=100, help="candidates of the evaluate call")
    ap.add_argument("--settings", nargs="+", choices=SETTINGS, default=list(SETTINGS))
    args = ap.parse_args(argv)
    if args.pairs < 1 or args.rows < 1:
        ap.error("--pairs and --rows must be at least 1")
    out: dict = {}
    for call in args.calls:
        runs: dict[str, list[dict]] = {s: [] for s in args.settings}
        for i in range(args.pairs):
            with tempfile.TemporaryDirectory() as tmp:
                store, cache = Path(tmp) / "programs", Path(tmp) / "jax"
                if "jax-cache" in args.settings:
                    _measure(call, args.rows, "jax-cache", store, cache)  # fills JAX's cache
                for setting in args.settings:
                    if setting == "store" and "cold" not in args.settings:
                        _measure(call, args.rows, "cold", store, cache)  # fills the store
                    runs[setting].append(_measure(call, args.rows, setting, store, cache))
            print(f"{call}: pair {i + 1} of {args.pairs} done", file=sys.stderr)
        out[call] = {s: {k: float(np.median([r[k] for r in runs[s]])) for k in ("import", "first", "warm")}
                     for s in args.settings}
    print(f"First call in a new process against a warm call (medians of {args.pairs}; seconds)\n")
    print("| call | setting | first | warm | first − warm | import |")
    print("|---|---|---:|---:|---:|---:|")
    for call, per in out.items():
        for s, m in per.items():
            print(f"| {call} | {s} | {m['first']:.2f} | {m['warm']:.3f} | {m['first'] - m['warm']:.2f} | "
                  f"{m['import']:.2f} |")
    return out


if __name__ == "__main__":
    main()
