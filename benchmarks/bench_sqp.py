"""The shortest-time programme of many moves solved by the batched SQP (dockjax.sqp, one
compiled, vmapped call) beside SciPy's SLSQP (dockjax.solve.min_time, one move at a time).

python benchmarks/bench_sqp.py [--preset wide] [--batches 1 8 64] [--repeats 3] [--slsqp 3] [--seed 0] [--rows 128]
python benchmarks/bench_sqp.py --batches 1 --repeats 1 --slsqp 0 --n-control 3 --max-iter 3  # quick

Moves: the preset's start and goal, each moved by up to ± 5 mm and ± 0.1° (a seeded draw),
knot intervals of the preset. Each move starts from the straight line at the shortest T the
box allows, slowed until the kernel certifies it. Per batch size B: the compile time of the
first call, the median time of a warm call (``--repeats``), programmes per second, and the
median and largest SQP iterations. Then for the first ``--slsqp`` moves: T from both solvers
after the certificate (:func:`dockjax.solve.certify_scaling`), their largest relative gap,
and SLSQP's median time per move.
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

from dockjax import solve, sqp
from dockjax.problem import make_problem


def _moves(base, count: int, seed: int):
    rng = np.random.default_rng(seed)
    step = np.array([5.0, 5.0, 5.0, 0.1, 0.1, 0.1])
    problems = []
    for _ in range(count):
        p = base.__class__(**{**base.identity(), "home": None,
                              "start": np.asarray(base.start) + rng.uniform(-1, 1, 6) * step,
                              "goal": np.asarray(base.goal) + rng.uniform(-1, 1, 6) * step})
        if (p.right_arm, p.jerk_nodes) != (base.right_arm, base.jerk_nodes):
            raise SystemExit("a drawn move changed the kernel's static settings; use a smaller draw")
        problems.append(p)
    return problems


def _start(p):
    n = p.n_intervals
    cert = solve.certify_scaling(p, solve.straight_line(p, [n * p.interval_bounds[0]])[0])
    if cert is None:
        raise SystemExit(f"the straight line of a move cannot be certified within the box ({n} intervals of at most "
                         f"{p.interval_bounds[1]:g} s): give more control points")
    x0 = cert[0]
    lo, hi = np.asarray(p.lower), np.asarray(p.upper)
    top = np.ones_like(lo)
    top[:n] -= 1e-6
    return np.clip((x0 - lo) / (hi - lo), 0.0, top), top, float(x0[:n].sum())


def _programme(params):
    def one(prob, u0, top, scale):
        m = prob.n_intervals * 8 * solve.critical_values(prob)

        def primal(u):
            return (solve._objective(u, prob, scale, 1.0),
                    solve.candidate_limits(prob, solve._x_of(prob, u)).reshape(-1))

        return sqp.run(u0, lambda u: solve._values.fun(prob, u, scale, 1.0), primal, jnp.zeros_like(u0), 1.0, top,
                       m, params)

    return jax.jit(jax.vmap(one))


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--preset", default="wide", choices=("paper", "wide"))
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 8, 64], help="batch sizes B")
    ap.add_argument("--repeats", type=int, default=3, help="warm calls per B (median)")
    ap.add_argument("--slsqp", type=int, default=3, help="moves also solved by SLSQP")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--n-control", type=int, default=5, help="free control points")
    ap.add_argument("--max-iter", type=int, default=150, help="most SQP iterations")
    ap.add_argument("--rows", type=int, default=sqp.Params().rows, help="constraints in each QP (nearest active)")
    args = ap.parse_args(argv)
    if min(args.batches) < 1 or args.repeats < 1 or args.slsqp < 0 or args.max_iter < 1 or args.rows < 1:
        ap.error("--batches, --repeats, --max-iter and --rows must be at least 1, --slsqp at least 0")
    out = {"batches": []}
    with jax.enable_x64(True):
        base = make_problem(args.preset, n_control=args.n_control)
        problems = _moves(base, max(max(args.batches), args.slsqp), args.seed)
        starts = [_start(p) for p in problems]
        run = _programme(sqp.Params(max_iter=args.max_iter, rows=args.rows))
        print(f"{args.preset} preset, n_control {args.n_control}, max_iter {args.max_iter}, rows {args.rows}")
        print(f"{'B':>6} {'compile s':>10} {'warm s':>8} {'programmes/s':>13} {'iter median':>12} {'iter max':>9}")
        for B in args.batches:
            stack = jax.tree.map(lambda *a: jnp.stack([jnp.asarray(v) for v in a]), *problems[:B])
            U, top, scale = (jnp.asarray(np.array(v)) for v in zip(*starts[:B]))
            t = time.perf_counter()
            st = jax.block_until_ready(run(stack, U, top, scale))
            first = time.perf_counter() - t
            times = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                st = jax.block_until_ready(run(stack, U, top, scale))
                times.append(time.perf_counter() - t)
            warm = float(np.median(times))
            k = np.asarray(st.k)
            row = {"B": B, "compile_s": first - warm, "warm_s": warm, "per_s": B / warm,
                   "iter_median": float(np.median(k)), "iter_max": int(k.max())}
            out["batches"].append(row)
            print(f"{B:>6} {row['compile_s']:>10.2f} {warm:>8.3f} {row['per_s']:>13.1f} {row['iter_median']:>12.0f} "
                  f"{row['iter_max']:>9}")
            if B == max(args.batches):
                U_last = np.asarray(st.u)
        gaps, slsqp_times = [], []
        for i in range(min(args.slsqp, len(U_last))):
            p = problems[i]
            lo, hi = np.asarray(p.lower), np.asarray(p.upper)
            mine = solve.certify_scaling(p, lo + U_last[i] * (hi - lo))
            t = time.perf_counter()
            ref = solve.min_time(p, lo + starts[i][0] * (hi - lo))
            slsqp_times.append(time.perf_counter() - t)
            T_mine = np.nan if mine is None else float(mine[1][0])
            T_ref = np.nan if ref is None else float(ref.F[0])
            gaps.append(abs(T_mine - T_ref) / T_ref)
            print(f"move {i}: T batched SQP {T_mine:.9g} s, SLSQP {T_ref:.9g} s")
        if gaps:
            out.update(largest_gap=float(np.max(gaps)), slsqp_s=float(np.median(slsqp_times)))
            print(f"largest relative gap {out['largest_gap']:.2e}; SLSQP median {out['slsqp_s']:.3f} s per move "
                  f"({1 / out['slsqp_s']:.1f} programmes/s)")
    return out


if __name__ == "__main__":
    main()
