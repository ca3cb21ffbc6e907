"""Evaluations per second of ``DockingProblem.evaluate`` beside a per-candidate SciPy loop.

    python benchmarks/bench_evaluate.py [--sizes 150 10000 100000] [--repeats 5] [--scipy-candidates 40]
                                        [--devices N]
    python benchmarks/bench_evaluate.py --sizes 16 --repeats 1 --scipy-candidates 4  # quick

The peer is what a user would write without dockjax: for each candidate, a
``scipy.interpolate.BSpline`` converted to ``PPoly``; T and the jerk objective by
Gauss–Legendre per span; the limits of the joints linear in the pose from the exact roots of
the derivative (``PPoly.roots``), the right arm's nonlinear joints by sampling each span
densely (400 points) and polishing the best sample with Newton steps on finite
differences. Both run in the same process, on the same candidates; medians of
``--repeats`` runs are quoted, compile time separately.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.interpolate import BSpline, PPoly

from dockjax import DockingProblem
from dockjax.problem import ROWS_PER_DEVICE

DEG = np.pi / 180


def _exp_derivs(e):
    """Derivatives 0..3 of ``exp(i e(t))`` from e and its derivatives (list of arrays)."""
    i = 1j
    base = np.exp(i * e[0])
    d1 = i * e[1]
    return [base, base * d1, base * (d1**2 + i * e[2]), base * (d1**3 + 3 * d1 * (i * e[2]) + i * e[3])]


def scipy_evaluate(problem: DockingProblem, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """F (2,), G (24,) of one candidate with SciPy (the peer)."""
    h = x[:6]
    t = np.cumsum(h)
    T = t[-1]
    u = np.r_[np.zeros(6), t[:5], np.full(6, T)]
    ctrl = np.vstack([np.tile(problem.start, (3, 1)), x[6:].reshape(5, 6), np.tile(problem.goal, (3, 1))])
    spl = BSpline(u, ctrl, 5)
    derivs = [spl] + [spl.derivative(k) for k in (1, 2, 3)]
    d2 = problem.arm_distance

    def right(ts, k):
        """k-th derivative of the right arm's three nonlinear joints at ts: (m, 3)."""
        p = [di(ts) for di in derivs]
        a = [pi[:, 3] * DEG for pi in p]
        b = [pi[:, 4] * DEG for pi in p]
        ea = _exp_derivs(a)[k]
        ep = _exp_derivs([ai + bi for ai, bi in zip(a, b)])[k]
        em = _exp_derivs([ai - bi for ai, bi in zip(a, b)])[k]
        r1 = p[k][:, 2] + d2 * 0.5 * (ep.real + em.real)  # cos a cos b
        r2 = p[k][:, 1] + d2 * ea.imag  # sin a
        r3 = -(p[k][:, 0] + d2 * 0.5 * (ep.imag - em.imag))  # cos a sin b
        return np.stack([r1, r2, r3], 1)

    xi, w = np.polynomial.legendre.leggauss(problem.jerk_nodes)
    ts = np.concatenate([0.5 * (u[5 + k] + u[6 + k]) + 0.5 * h[k] * xi for k in range(6)])
    ws = np.concatenate([0.5 * h[k] * w for k in range(6)])
    p3 = derivs[3](ts)
    jerk = np.concatenate([np.stack([-p3[:, 2], p3[:, 1], -p3[:, 0], p3[:, 5]], 1), right(ts, 3), -p3[:, 5:6]], 1)
    f2 = np.sum(np.sqrt(ws @ (jerk * jerk) / T))

    G = np.empty((8, 3))
    for j, (coord, sign) in {0: (2, -1), 1: (1, 1), 2: (0, -1), 3: (5, 1), 7: (5, -1)}.items():
        poly = PPoly.from_spline(BSpline(u, sign * ctrl[:, coord], 5))
        for k in range(3):
            q = poly.derivative(k) if k else poly
            roots = q.derivative().roots(extrapolate=False)
            cand = np.r_[u[5:12], roots[np.isfinite(roots)]]
            G[j, k] = np.nanmax(np.abs(q(cand) - (problem.home[j] if k == 0 else 0.0)))
    # right arm: dense samples (400 per span), the best refined by a parabola through its
    # neighbours
    grid = np.concatenate([np.linspace(u[5 + k], u[6 + k], 400) for k in range(6)])
    for k in range(3):
        vals = np.abs(right(grid, k) - (problem.home[4:7] if k == 0 else 0.0))
        i = np.clip(np.argmax(vals, axis=0), 1, len(grid) - 2)
        for r in range(3):
            y0, y1, y2 = vals[i[r] - 1, r], vals[i[r], r], vals[i[r] + 1, r]
            den = y0 - 2 * y1 + y2
            vertex = y1 - 0.125 * (y2 - y0) ** 2 / den if den < 0 else y1
            G[4 + r, k] = max(vals[:, r].max(), vertex)
    return np.array([T, f2]), (G / problem.limits - 1).reshape(-1)


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[150, 10_000, 100_000])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--scipy-candidates", type=int, default=40)
    ap.add_argument("--devices", type=int, default=None,
                    help="CPU devices the rows are shared out over (default: one per usable core)")
    args = ap.parse_args(argv)
    if args.repeats < 1 or args.scipy_candidates < 1 or min(args.sizes) < 1:
        ap.error("--sizes, --repeats and --scipy-candidates must be >= 1")
    from dockjax.runtime import claim_devices

    try:
        devices = claim_devices(args.devices)  # before any JAX computation
    except ValueError as exc:
        ap.error(str(exc))
    print(f"{devices} CPU device(s); evaluate shares the rows out over them (at most one per {ROWS_PER_DEVICE} rows)")
    problem = DockingProblem()
    rng = np.random.default_rng(0)
    Xs = rng.uniform(problem.lower, problem.upper, (args.scipy_candidates, problem.n_var))
    t_scipy = median_time(lambda: [scipy_evaluate(problem, x) for x in Xs], 3) / len(Xs)
    ref = np.array([np.r_[f, g] for f, g in (scipy_evaluate(problem, x) for x in Xs)])
    scipy_rate = 1.0 / t_scipy
    print(f"scipy per-candidate loop: {scipy_rate:,.0f} evaluations/s (median over {len(Xs)} candidates)")
    for screen in (True, False):
        F, G = problem.evaluate(Xs, screen=screen)
        agree_f = np.max(np.abs(F - ref[:, :2]) / np.abs(ref[:, :2]))
        near = np.abs(ref[:, 2:]) < 0.04
        agree_g = np.nanmax(np.abs(G - ref[:, 2:]))
        agree_near = np.nanmax(np.abs(G - ref[:, 2:])[near]) if near.any() else float("nan")
        print(f"  screen={screen}: F agrees to {agree_f:.1e} rel; G to {agree_g:.1e} "
              f"({agree_near:.1e} on columns within 4 % of their limit)")
    print(f"{'n':>8} {'precision':>9} {'screen':>6} {'devices':>7} {'compile s':>9} {'evals/s':>12} {'x scipy':>8}")
    layouts = [("float64", True, None), ("float32", True, None), ("float64", False, None)]
    if devices > 1:  # the peer layout: one device (XLA's intra-op threads)
        layouts.append(("float64", True, 1))
    for n in args.sizes:
        X = rng.uniform(problem.lower, problem.upper, (n, problem.n_var))
        for precision, screen, d in layouts:
            run = lambda: problem.evaluate(X, precision=precision, screen=screen, devices=d)  # noqa: E731
            t0 = time.perf_counter()
            run()
            compile_s = time.perf_counter() - t0
            rate = n / median_time(run, args.repeats)
            used = 1 if d == 1 else min(devices, -(-n // ROWS_PER_DEVICE))
            print(f"{n:>8} {precision:>9} {str(screen):>6} {used:>7} {compile_s:>9.2f} {rate:>12,.0f} "
                  f"{rate / scipy_rate:>8.0f}")


if __name__ == "__main__":
    main()
