"""Reproduce the paper's comparison (§5) with statistics: four algorithms × 31 seeds.

    python experiments/compare.py                      # both presets, paper settings
    python experiments/compare.py --seeds 2 --pop 12 --iters 5 --out /tmp/cmp   # a quick check

Writes into ``--out/<preset>/``: indicators.{csv,md} (median, IQR, best run, rank-sum p
against IMOCS of ONVG, GD, SP, IGD, HV), runs.csv (per run), table3.{csv,md}, table4.{csv,md}
and chosen.json (the three trajectories of Table 4 with every joint's maximum |velocity| and
|acceleration| beside its limit), fronts.png, left_arm_xyz.png, joints.png,
convergence.png, raw.npz (every final population), reference.txt and best_known.npz (the
reference front). Rows: the four algorithms and "imocs+refine" (IMOCS finished by gradient
refinement). Presets: ``paper`` (h ∈ [3.5, 10] s) and ``wide`` (h ∈ [0.5, 10] s).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import tyro

ALGOS = ("nsga2", "mopso", "mocs", "imocs")


@dataclass(frozen=True)
class Args:
    out: Path = Path("results/compare")
    """Results folder (created; one sub-folder per preset)."""
    seeds: int = 31
    """Runs per algorithm (seeds 0 .. seeds-1)."""
    pop: int = 150
    """Population size."""
    iters: int = 100
    """Iterations per run."""
    presets: tuple[Literal["paper", "wide"], ...] = ("paper", "wide")
    """Problem presets to run."""
    algorithms: tuple[Literal["nsga2", "mopso", "mocs", "imocs"], ...] = ALGOS
    """Algorithms to compare (IMOCS is the baseline of the rank-sum tests)."""
    refine_steps: int = 100
    """Gradient-refinement steps of the "IMOCS + refine" rows (every IMOCS run's final
    population polished by dockjax.refine); 0 leaves them out."""
    best_known: bool = True
    """Use the best-known front (ε-constraint sweep with gradient refinement, computed from
    the problem alone; cached in <out>/<preset>/best_known.npz) as the indicators' reference
    front; --no-best-known uses the union of the algorithms' final sets instead."""
    best_known_points: int = 150
    """Time caps of the best-known front's ε-constraint sweep (>= 2)."""
    best_known_steps: int = 600
    """Refinement steps per time cap of the best-known front."""
    devices: int | None = None
    """CPU devices the work is shared over (the runs are bit-identical for any count, the
    refinement's scores equal to rounding). Default: one per usable core."""


def main(args: Args) -> int:
    errors = []
    if args.seeds < 1:
        errors.append(f"--seeds must be >= 1, got {args.seeds}")
    if args.pop < 4:
        errors.append(f"--pop must be >= 4, got {args.pop}")
    if args.iters < 1:
        errors.append(f"--iters must be >= 1, got {args.iters}")
    if not args.presets:
        errors.append("--presets must name at least one preset")
    if not args.algorithms:
        errors.append("--algorithms must name at least one algorithm")
    if args.best_known and args.best_known_points < 2:
        errors.append(f"--best-known-points must be >= 2, got {args.best_known_points}")
    if args.best_known and args.best_known_steps < 1:
        errors.append(f"--best-known-steps must be >= 1, got {args.best_known_steps}")
    if args.refine_steps < 0:
        errors.append(f"--refine-steps must be >= 0, got {args.refine_steps}")
    if args.devices is not None and args.devices < 1:
        errors.append(f"--devices must be >= 1, got {args.devices}")
    if not errors:
        created = not args.out.exists()
        try:
            args.out.mkdir(parents=True, exist_ok=True)
            probe = args.out / ".write-test"
            probe.write_text("")
            probe.unlink()
        except OSError as exc:
            errors.append(f"--out {args.out} cannot be written: {exc}")
            if created and args.out.is_dir() and not any(args.out.iterdir()):
                args.out.rmdir()
    if errors:
        print("error: " + "; ".join(errors), file=sys.stderr)
        return 2
    from dockjax.cli import claim_devices, enable_compilation_cache

    claim_devices(args.devices)  # before any JAX computation: each device runs its share of the runs
    from dockjax.study import (best_known_cached, make_problem, refine_rows, run_study, study_right_arm,
                               summary_table, write_study)

    enable_compilation_cache()
    t0 = time.perf_counter()
    # one right-arm setting and one refinement shape for everything: shared compilations
    right_arm = study_right_arm(args.presets)
    rows = refine_rows(args.seeds * args.pop, args.best_known_points)
    for preset in args.presets:
        best = None
        if args.best_known:
            (args.out / preset).mkdir(parents=True, exist_ok=True)
            best = best_known_cached(make_problem(preset, right_arm), args.out / preset / "best_known.npz",
                                     log=lambda m, p=preset: print(f"[{p}] {m}"),
                                     n_points=args.best_known_points, steps=args.best_known_steps,
                                     rows=rows)
        study = run_study(preset, algorithms=args.algorithms, seeds=range(args.seeds),
                          pop_size=args.pop, n_iter=args.iters, refine_steps=args.refine_steps,
                          best_known=best, right_arm=right_arm, refine_rows=rows)
        t1 = time.perf_counter()
        files = write_study(study, args.out)
        print(f"[{preset}] reference front: {study.reference_description}")
        for row in summary_table(study):
            print(f"[{preset}] {row['algorithm']:>12}: HV {row['HV_median']:.4f} (IQR {row['HV_iqr']:.4f}, "
                  f"{100 * row['HV_fraction_median']:.2f} % of the reference's), "
                  f"IGD {row['IGD_median']:.4f}, GD {row['GD_median']:.5f}, SP {row['SP_median']:.5f}, "
                  f"ONVG {row['ONVG_median']:.0f}")
        print(f"[{preset}] wrote {len(files)} files to {args.out / preset} in {time.perf_counter() - t1:.1f} s")
    print(f"wall time: {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(tyro.cli(Args)))
