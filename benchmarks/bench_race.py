"""Racing against the full grid: how many runs the race saves, and whether its winner is
one of the settings the full grid cannot tell from the best.

    python benchmarks/bench_race.py [--rho 0.1 0.3 0.5 0.7 0.9] [--alpha-max 0.1 1 3 10 30]
                                    [--seeds 31] [--pop 150] [--iters 100] [--min-seeds 5] [--chunk 40]
                                    [--reference best-known] [--devices N]
    python benchmarks/bench_race.py --seeds 3 --pop 8 --iters 3 --min-seeds 2 --chunk 2 --reference pilot  # quick

Runs the full grid (every ρ × α_max setting of IMOCS on every seed) and the race over the
same grid and seed budget, in the same process, against the same reference front (the
best-known front, or with ``--reference pilot`` the front of a pilot chunk, the same seeds
in both studies), both study folders in a temporary directory, then prints the full grid's
best setting and its tied set (Wilcoxon signed-rank against the best, Holm, α = 0.05), the
race's survivors and winner, the runs each used and their wall times.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rho", type=float, nargs="+", default=[0.1, 0.3, 0.5, 0.7, 0.9])
    ap.add_argument("--alpha-max", type=float, nargs="+", default=[0.1, 1.0, 3.0, 10.0, 30.0])
    ap.add_argument("--seeds", type=int, default=31)
    ap.add_argument("--pop", type=int, default=150)
    ap.add_argument("--iters", type=int, default=100)
    ap.add_argument("--min-seeds", type=int, default=5)
    ap.add_argument("--chunk", type=int, default=40, help="runs per compiled call")
    ap.add_argument("--reference", default="best-known", choices=("best-known", "pilot"),
                    help="the studies' reference front")
    ap.add_argument("--devices", type=int, default=None, help="CPU devices (default: one per usable core)")
    args = ap.parse_args(argv)
    from dockjax.runtime import claim_devices, enable_compilation_cache

    try:
        devices = claim_devices(args.devices)  # before any JAX computation
    except ValueError as exc:
        ap.error(str(exc))
    enable_compilation_cache()
    from dockjax.sweep import load_table, make_config, prepare_folder, run_sweep, summarise
    from dockjax.sweep.design import ParamSpec

    specs = [ParamSpec("rho", "imocs", values=tuple(args.rho)), ParamSpec("alpha_max", "imocs",
                                                                         values=tuple(args.alpha_max))]
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, race in (("full grid", False), ("race", True)):
            cfg, _ = make_config(algorithms=("imocs",), params=specs, pop=(args.pop,), iters=(args.iters,),
                                 seeds=args.seeds, chunk=args.chunk, reference=args.reference, race=race,
                                 race_min_seeds=args.min_seeds)
            out = Path(tmp) / name.replace(" ", "_")
            prepare_folder(out, cfg)
            t0 = time.perf_counter()
            run_sweep(cfg, out, progress=False, log=lambda m: None)
            seconds = time.perf_counter() - t0
            cols = load_table(out)[0]
            results[name] = (cfg, summarise(cfg, cols), len(cols["setting"]), seconds)
    cfg, full, n_full, t_full = results["full grid"]
    _, race, n_race, t_race = results["race"]
    c = full.comparison
    tied = {int(np.flatnonzero(full.finalists)[j]) for j in np.flatnonzero(c.tied)}
    best_full = int(np.flatnonzero(full.finalists)[c.best])
    rc = race.comparison
    winner = int(np.flatnonzero(race.finalists)[rc.best])
    survivors = np.flatnonzero(race.finalists)
    label = lambda i: cfg.settings[i].label  # noqa: E731
    print(f"{devices} CPU device(s); {len(cfg.settings)} settings, {args.seeds} seeds, pop {args.pop}, "
          f"{args.iters} iterations; {args.reference} reference front")
    print(f"full grid: {n_full} runs in {t_full:.1f} s; best {label(best_full)}; {len(tied)} settings tied with "
          f"the best (Wilcoxon vs best, Holm, alpha 0.05): {sorted(tied)}")
    print(f"race: {n_race} runs ({100 * n_race / n_full:.1f} % of the full grid) in {t_race:.1f} s, "
          f"{len(race.rounds)} rounds, survivors {survivors.tolist()} after {int(race.rows[winner]['runs'])} seeds; "
          f"winner {label(winner)}")
    print(f"the race's winner is {'in' if winner in tied else 'NOT in'} the full grid's tied-with-best set; "
          f"the survivors in it: {sum(int(s) in tied for s in survivors)} of {len(survivors)}")


if __name__ == "__main__":
    main()
