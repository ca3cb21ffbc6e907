"""Hyper-parameter sweeps that never lose work (IMOCS's ρ × α_max × population size × seeds).

    python experiments/sweep.py                                   # default study, a few minutes
    python experiments/sweep.py --pop 100 150 200 --seeds 5 --out results/sweep-pop
    python experiments/sweep.py --rho 0.2 0.4 0.6 --alpha-max 0.05 0.1 --iters 100
    python experiments/sweep.py --algorithm nsga2 --pop 50 100 150   # ρ/α_max do not apply
    python experiments/sweep.py --backend dask --workers 2          # a Dask LocalCluster
    python experiments/sweep.py --backend dask --scheduler tcp://host:8786
    python experiments/sweep.py --help

Every finished chunk of runs is written atomically into ``--out/chunks/``; after an
interruption (Ctrl-C, kill -9) re-run the same command and only the missing chunks run.
Results: ``runs.csv`` (one row per run: algorithm, pop, rho, alpha_max, seed, iterations,
HV, IGD, IGD+, GD, SP, ONVG, T_min, T_max, jerk_min, jerk_max, chunk, wall_s),
``summary.{csv,md}`` (per setting, best median HV first), ``fronts.npz``, heat maps of the
median HV over ρ × α_max per population size, HV against population size, and the fronts of
the best and worst settings. Indicators are computed against a reference front and
normalisation fixed at sweep start (``reference.npz``). Bad input exits with code 2 before
any compilation. Details: the docstring of ``dockjax/sweep.py``.
"""

from __future__ import annotations

import sys

from dockjax.sweep import main

if __name__ == "__main__":
    sys.exit(main())
