"""Score a random population and print the best feasible candidates: ``dockjax demo``.

    python experiments/demo.py --n 100000
"""

import sys

from dockjax.cli import main

if __name__ == "__main__":
    sys.exit(main(["demo", *sys.argv[1:]]))
