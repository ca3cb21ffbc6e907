"""Cost of the right arm's treatments (``right_arm``) on four configurations.

    python benchmarks/bench_right_arm.py [--n 2400] [--repeats 5] [--configs NAME ...] [--devices N]
    python benchmarks/bench_right_arm.py --n 16 --repeats 1 --configs paper  # quick

For each configuration — the paper's (pitch and yaw move by 0.2°), the wide preset
(h >= 0.5 s), a slow 1.8° attitude move with D2 = 3 m, and a 10° move — and each of
``"bound"``, ``"adaptive"`` and ``"taylor"``, screened and not: evaluations per second of
``DockingProblem.evaluate`` on the same ``--n`` random candidates of the decision box
(median of ``--repeats`` calls, after a first call that compiles), the ratio to
``"bound"``, and which treatment ``"auto"`` picks. Also the share of candidates that the
``"adaptive"`` treatment sends to the Taylor models. ``--configs`` picks some of the
configurations by name (default all four); each draws its candidates from its own seed
(its place in the list of four), whichever others run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

CONFIGS = {
    "paper": {},
    "wide": dict(interval_bounds=(0.5, 10.0)),
    "1.8 deg, D2 3 m": dict(start=(760.0, -20.0, -1400.0, 0.9, 0.3, 185.0),
                            goal=(760.0, -20.0, -1400.0, -0.9, -0.2, 185.0), arm_distance=3000.0,
                            interval_bounds=(5.0, 12.0)),
    "10 deg": dict(start=(775.0, -35.0, -1315.0, 10.0, -10.0, 190.0), travel=(3000.0, 3000.0, 3000.0, 15.0),
                   velocity=(400.0, 250.0, 250.0, 6.8)),
}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=2400)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS), metavar="NAME",
                    help=f"configurations to time (default all: {', '.join(map(repr, CONFIGS))})")
    ap.add_argument("--devices", type=int, default=None, help="CPU devices (default: one per usable core)")
    args = ap.parse_args(argv)
    if args.n < 1 or args.repeats < 1:
        ap.error("--n and --repeats must be >= 1")
    from dockjax.runtime import claim_devices

    try:
        devices = claim_devices(args.devices)  # before any JAX computation
    except ValueError as exc:
        ap.error(str(exc))
    import jax
    import jax.numpy as jnp

    from dockjax import DockingProblem
    from dockjax.problem import score_batch

    need_of = jax.jit(lambda p, X: score_batch(p, X, True, with_need=True)[2])
    print(f"{devices} CPU device(s); {args.n} random candidates of each box; medians of {args.repeats} calls")
    print(f"{'configuration':>16} {'auto':>8} {'to Taylor':>9} {'mode':>8} {'screen':>6} {'evals/s':>10} "
          f"{'x bound':>7}")
    for name in args.configs:
        kw = CONFIGS[name]
        rng = np.random.default_rng(list(CONFIGS).index(name))
        auto = DockingProblem(**kw).right_arm
        problems = {m: DockingProblem(**kw, right_arm=m) for m in ("bound", "adaptive", "taylor")}
        X = rng.uniform(problems["bound"].lower, problems["bound"].upper, (args.n, problems["bound"].n_var))
        with jax.enable_x64(True):
            share = float(np.mean(np.asarray(need_of(problems["bound"], jnp.asarray(X)))))
        for screen in (True, False):
            base = None
            for mode, p in problems.items():
                p.evaluate(X, screen=screen)
                times = []
                for _ in range(args.repeats):
                    t0 = time.perf_counter()
                    p.evaluate(X, screen=screen)
                    times.append(time.perf_counter() - t0)
                rate = args.n / float(np.median(times))
                base = base or rate
                print(f"{name:>16} {auto:>8} {100 * share:>8.1f}% {mode:>8} {str(screen):>6} {rate:>10,.0f} "
                      f"{rate / base:>7.2f}", flush=True)


if __name__ == "__main__":
    main()
