"""Score a random population and print the best feasible candidates: ``dockjax demo``.

    python experiments/demo.py --n 100000
"""

import sys

from dockjax.cli import exit_with, main

if __name__ == "__main__":
    exit_with(main(["demo", *sys.argv[1:]]))
