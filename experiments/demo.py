"""Score a random population of the docking problem and print the best feasible candidates.

    python experiments/demo.py --n 100000
"""

from dockjax.cli import demo_main

if __name__ == "__main__":
    demo_main()
