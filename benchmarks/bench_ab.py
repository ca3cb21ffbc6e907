"""``DockingProblem.evaluate`` of this checkout against another git revision, in one process.

    python benchmarks/bench_ab.py --base HEAD~1 [--presets paper wide] [--sizes 150 10000]
                                  [--repeats 15] [--devices N]
    python benchmarks/bench_ab.py --base HEAD --sizes 16 --repeats 1  # quick

The base revision's ``dockjax`` package is exported with ``git archive`` into a temporary
folder and imported as ``dockjax_base`` (the package uses relative imports only), so both
versions score the same candidates in the same process, interleaved call by call (A, B,
A, B, …): a spell of load on this shared machine slows both alike. Prints, per preset,
size and screen setting, the median time of each version, the ratio (this checkout over
the base; below 1 is faster) with the 25–75 % range of the per-pair ratios, and whether
the two versions' F and G are bit-identical. The base package is removed from
``sys.path`` and ``sys.modules`` when the comparison ends, so ``main`` can run again in the
same process.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PRESETS = {"paper": {}, "wide": dict(interval_bounds=(0.5, 10.0))}


@contextlib.contextmanager
def base_package(rev: str, where: Path):
    """The ``dockjax`` package of git revision ``rev``, exported into ``where`` and imported
    as ``dockjax_base`` for the duration of the block (then removed from ``sys.path`` and
    ``sys.modules``)."""
    data = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", rev, "dockjax"],
                          check=True, capture_output=True).stdout
    with tarfile.open(fileobj=BytesIO(data)) as tar:
        tar.extractall(where, filter="data")
    (where / "dockjax").rename(where / "dockjax_base")
    sys.path.insert(0, str(where))
    try:
        yield importlib.import_module("dockjax_base")
    finally:
        sys.path.remove(str(where))
        for name in [m for m in sys.modules if m == "dockjax_base" or m.startswith("dockjax_base.")]:
            del sys.modules[name]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, help="git revision to compare against (e.g. HEAD~1, a tag)")
    ap.add_argument("--presets", nargs="+", default=["paper"], choices=sorted(PRESETS))
    ap.add_argument("--sizes", type=int, nargs="+", default=[150, 10_000])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--devices", type=int, default=None, help="CPU devices (default: one per usable core)")
    args = ap.parse_args(argv)
    if args.repeats < 1 or min(args.sizes) < 1:
        ap.error("--sizes and --repeats must be >= 1")
    from dockjax.runtime import claim_devices

    try:
        devices = claim_devices(args.devices)  # before any JAX computation
    except ValueError as exc:
        ap.error(str(exc))
    import dockjax

    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        try:
            base = stack.enter_context(base_package(args.base, Path(tmp)))
        except subprocess.CalledProcessError as exc:
            ap.error(f"--base {args.base!r}: git archive failed: {exc.stderr.decode().strip()}")
        print(f"this checkout against {args.base}; {devices} CPU device(s); medians of {args.repeats} "
              f"interleaved pairs")
        print(f"{'preset':>6} {'n':>7} {'screen':>6} {'base ms':>9} {'this ms':>9} {'ratio':>6} "
              f"{'25-75 %':>12} {'same F, G':>9}")
        rng = np.random.default_rng(0)
        for preset in args.presets:
            pa = base.DockingProblem(**PRESETS[preset])
            pb = dockjax.DockingProblem(**PRESETS[preset])
            for n in args.sizes:
                X = rng.uniform(pb.lower, pb.upper, (n, pb.n_var))
                for screen in (True, False):
                    ra, rb = pa.evaluate(X, screen=screen), pb.evaluate(X, screen=screen)  # compile
                    same = all(np.array_equal(a, b) for a, b in zip(ra, rb))
                    ta, tb = [], []
                    for _ in range(args.repeats):
                        for p, out in ((pa, ta), (pb, tb)):
                            t0 = time.perf_counter()
                            p.evaluate(X, screen=screen)
                            out.append(time.perf_counter() - t0)
                    ratios = np.asarray(tb) / np.asarray(ta)
                    q1, q3 = np.percentile(ratios, [25, 75])
                    print(f"{preset:>6} {n:>7} {str(screen):>6} {1e3 * np.median(ta):>9.2f} "
                          f"{1e3 * np.median(tb):>9.2f} {np.median(tb) / np.median(ta):>6.3f} "
                          f"{q1:>5.3f}-{q3:<6.3f} {str(same):>9}", flush=True)


if __name__ == "__main__":
    main()
