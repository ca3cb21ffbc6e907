"""Hyper-parameter sweeps that never lose work: ``dockjax sweep`` (see ``docs/cli.md``).

    python experiments/sweep.py --pop 150                          # the main job
    python experiments/sweep.py --pop 100 150 200 --seeds 5 --out results/sweep-pop
    python experiments/sweep.py --algorithm nsga2 --pop 50 100 150
    python experiments/sweep.py --backend dask --workers 2
    python experiments/sweep.py --help
"""

import sys

from dockjax.cli import exit_with, main

if __name__ == "__main__":
    exit_with(main(["sweep", *sys.argv[1:]]))
