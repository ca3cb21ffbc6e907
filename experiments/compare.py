"""The paper's comparison with statistics: ``dockjax compare`` (see ``docs/cli.md``).

    python experiments/compare.py                      # both presets, the paper's settings
    python experiments/compare.py --seeds 2 --pop 12 --iters 5 --out /tmp/cmp   # a quick check
"""

import sys

from dockjax.cli import exit_with, main

if __name__ == "__main__":
    exit_with(main(["compare", *sys.argv[1:]]))
