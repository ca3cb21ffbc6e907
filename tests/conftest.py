"""Shared fixtures. ``tests/reference.py`` is the independent reference (no dockjax code).

The suite runs under ``pytest -n 2`` (pytest-xdist). Expensive artefacts — a compare run, a
sweep folder, a plan of the wide preset, pymoo's NSGA-II on ZDT1 — are made once per test
run, whichever worker asks first (:func:`run_once`), and shared with the other worker.
Property tests take their example counts from a hypothesis profile: ``ci`` (the default)
or ``thorough`` (``--hypothesis-profile thorough``) for a longer hunt.
"""

from __future__ import annotations

import fcntl
import gc
import os
import pathlib
import pickle
import sys
from typing import Any, Callable

import pytest
from hypothesis import HealthCheck, settings

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


# Test processes (both xdist workers) and the few CLI subprocesses of the tests share JAX's
# persistent compilation cache, so a computation compiled in one is reused by the others.
# Test-only; the library never sets it.
CACHE = ROOT / ".pytest-jax-cache"
os.environ.setdefault("DOCKJAX_CACHE", str(CACHE))
os.environ.setdefault("DOCKJAX_FRONTS", str(CACHE / "fronts"))  # best-known fronts of the studies
os.environ.setdefault("DOCKJAX_PROGRAMS", str(CACHE / "programs"))  # dockjax's store of compiled programs

settings.register_profile("ci", max_examples=25, deadline=None, database=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("thorough", max_examples=400, deadline=None, database=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


# XLA:CPU's classic fusion emitters: the suite's programs compile in about 30 % less time
# than with the default (MLIR) emitters, and run about as fast; results differ from the
# default only in rounding (the jerk integral's last bits). LLVM optimisation level 2
# instead of XLA's default 3: NSGA-II's program compiles in less than half the time, the
# kernel's and the optimisers' on the docking problem in 3-17 % less, run times within
# about 20 %, results bit-identical (docs/performance.md, benchmarks/bench_compile.py).
# Set before JAX starts, so the test processes and their CLI subprocesses compile this way;
# tests/test_xla_settings.py runs its subprocess with JAX's default emitters, so both code
# generators are exercised.
CLASSIC_EMITTERS = "--xla_cpu_use_fusion_emitters=false"
TEST_FLAGS = (CLASSIC_EMITTERS, "--xla_backend_optimization_level=2")
GC_THRESHOLD = 50_000
"""Allocations between two young-generation collections in the test processes (Python's default: 700)."""


SHORT_IMOCS = dict(pop_size=8, max_iter=3, rho=[0.3, 0.5], alpha_max=[0.1, 0.2])
"""Two short IMOCS runs of the docking problem with per-run hyper-parameters and a
hypervolume history, as the README's ``optimize`` snippet and a sweep's chunk run them: one
compiled program for all of them (through the persistent compilation cache)."""


def short_imocs_runs(problem):
    """:data:`SHORT_IMOCS` on ``problem``, seeds 0 and 1."""
    from dockjax.algorithms import imocs
    from dockjax.optimize import optimize

    return optimize("imocs", problem, params=imocs.Params(**SHORT_IMOCS), seeds=[0, 1], hv_ref=[60, 5])


def pytest_configure(config):
    flags = os.environ.get("XLA_FLAGS", "").split()
    os.environ["XLA_FLAGS"] = " ".join(flags + [f for f in TEST_FLAGS if f not in flags])
    import jax

    CACHE.mkdir(exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(CACHE))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)  # the workers share even small programs
    jax.devices()  # one CPU device per test process, whatever a command run in-process asks for
    # Tracing and lowering make many short-lived objects, and the cyclic collector's default
    # thresholds run it every 700 allocations: with the modules loaded so far frozen out of
    # its scans and a higher first threshold, JAX traces 20-35 % faster (a kernel programme).
    gc.freeze()
    gc.set_threshold(GC_THRESHOLD, 20, 20)


FIRST = ("tests/test_bulk.py",)
"""Test files that start the run: the batched planner's program takes the longest to
compile, and ``bench_plan.py``'s quick form (at the end) loads it from the store."""
LONGEST_QUICK_FORM = "tests/test_benchmarks.py::test_quick_form_runs_in_process[bench_plan]"
"""The longest benchmark quick form, the first of them, so that the other worker runs the
rest meanwhile instead of waiting for it at the end of the run."""


def _order(item) -> int:
    if item.nodeid.startswith(FIRST):
        return 0
    if item.nodeid == LONGEST_QUICK_FORM:
        return 2
    return 3 if item.nodeid.startswith("tests/test_benchmarks.py") else 1


def pytest_collection_modifyitems(config, items):
    """:data:`FIRST` first; the benchmarks' quick forms last (the longest of them first): by
    then the other tests have compiled most of their programs into the persistent cache and
    the store."""
    items.sort(key=_order)


@pytest.fixture(scope="module")
def run_once(tmp_path_factory) -> Callable[[str, Callable[[pathlib.Path], Any]], Any]:
    """``run_once(name, make)``: ``make(folder)`` computed once per test run across the xdist
    workers (a file lock; the value pickled beside its folder), then returned to every
    caller (a module after the first loads the pickle). ``folder`` is a fresh directory
    shared by the workers, for files ``make`` writes."""
    root = tmp_path_factory.getbasetemp()
    root = root.parent if os.environ.get("PYTEST_XDIST_WORKER") else root  # shared by the workers
    values: dict[str, Any] = {}

    def get(name: str, make: Callable[[pathlib.Path], Any]) -> Any:
        if name in values:
            return values[name]
        folder = root / f"shared-{name}"
        with open(root / f"shared-{name}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            done = root / f"shared-{name}.pkl"
            if done.exists():
                value = pickle.loads(done.read_bytes())
            else:
                folder.mkdir(exist_ok=True)
                value = make(folder)
                done.write_bytes(pickle.dumps(value))
        values[name] = value
        return value

    return get


@pytest.fixture
def x64():
    """Run a test with JAX float64 enabled, restoring the caller's setting afterwards.

    Only the kinematics helpers (plain ``jax.numpy`` functions) need it; the problem's
    ``evaluate`` must compute in float64 without the caller enabling it, so problem tests
    do not use this fixture.
    """
    import jax

    with jax.enable_x64(True):
        yield


def _cli(argv: list[str]) -> tuple[int, str]:
    """``dockjax ARGV`` in this process: (exit code, what it printed)."""
    import contextlib
    import io

    from dockjax import cli

    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        code = cli.main(argv)
    return code, text.getvalue()


@pytest.fixture(scope="module")
def paper_plan(run_once):
    """``dockjax plan --rate 200 --n-front 3 --export ros2 axes`` (the paper's move, the compromise of Eq. 26;
    three time caps of the front to choose from), made once: its folder."""
    def make(folder):
        code, _ = _cli(["plan", "--rate", "200", "--n-front", "3", "--export", "ros2", "axes", "--out",
                        str(folder / "plan")])
        assert code == 0
        return folder / "plan"

    return run_once("paper-plan", make)


@pytest.fixture(scope="module")
def wide_time_plan(run_once):
    """The wide preset's shortest-time plan, explained and checked by re-planning:
    ``dockjax plan --select time --interval-bounds 0.5 10 --explain --rate 200 --n-front 2``,
    made once.
    → (its folder, what it printed)."""
    def make(folder):
        code, text = _cli(["plan", "--select", "time", "--interval-bounds", "0.5", "10", "--explain", "--rate", "200",
                           "--n-front", "2", "--out", str(folder / "plan")])
        assert code == 0
        return folder / "plan", text

    return run_once("wide-time-plan", make)


@pytest.fixture(scope="module")
def wide_compromise_plan(run_once):
    """``plan(make_problem("wide"), weights=(1, 1), n_front=3)`` with its sensitivities
    checked, made once."""
    from dockjax.plan import plan
    from dockjax.problem import make_problem

    return run_once("wide-compromise-plan", lambda _: plan(make_problem("wide"), weights=(1.0, 1.0), n_front=3))


@pytest.fixture(scope="module")
def imocs_plan(run_once):
    """``plan(weights=(1, 0), method="imocs", pop_size=8, n_iter=3, rate=50)``, made once
    (the compiled run of tests/test_cuckoo.py's single run)."""
    from dockjax.plan import plan

    return run_once("imocs-plan", lambda _: plan(weights=(1, 0), method="imocs", pop_size=8, n_iter=3, rate=50,
                                                  refine_steps=0))


if os.environ.get("DOCKJAX_LOG_COMPILES"):  # diagnostics: every compilation, per worker
    import logging

    _handler = logging.FileHandler(f"/tmp/compiles-{os.environ.get('PYTEST_XDIST_WORKER', 'main')}.log")
    _handler.setFormatter(logging.Formatter("%(created).3f %(message)s"))
    logging.getLogger("jax").addHandler(_handler)
    logging.getLogger("jax").setLevel(logging.WARNING)

    @pytest.fixture(autouse=True)
    def _mark_test(request):
        logging.getLogger("jax").warning("TEST %s", request.node.nodeid)
        yield


@pytest.fixture(scope="module")
def pymoo_zdt1_igd(run_once) -> float:
    """The median IGD of pymoo's NSGA-II on its own ZDT1 (population 100, 100 generations,
    seeds 0-4) against 1000 points of the analytic front, made once: the yardstick of the
    optimisers' ZDT1 tests."""
    def make(_):
        import numpy as np
        from pymoo.algorithms.moo.nsga2 import NSGA2
        from pymoo.optimize import minimize
        from pymoo.problems import get_problem

        x = np.linspace(0.0, 1.0, 1000)
        front = np.column_stack([x, 1.0 - np.sqrt(x)])
        values = []
        for seed in range(5):
            F = minimize(get_problem("zdt1"), NSGA2(pop_size=100), ("n_gen", 100), seed=seed).F
            values.append(float(np.sqrt(((front[:, None, :] - F[None]) ** 2).sum(-1)).min(1).mean()))
        return float(np.median(values))

    return run_once("pymoo-zdt1-igd", make)


@pytest.fixture(scope="module")
def tiny_sweep(run_once):
    """``tests.sweeps.TINY`` run to the end in this process, once: (folder, what it printed)."""
    from tests import sweeps

    def make(folder):
        code, text = sweeps.run(folder / "full")
        assert code == 0
        return folder / "full", text

    return run_once("sweep-tiny", make)


@pytest.fixture(scope="module")
def tiny_race(run_once):
    """``tests.sweeps.RACE`` run to the end in this process, once: (folder, what it printed)."""
    from tests import sweeps

    def make(folder):
        code, text = sweeps.run(folder / "race", sweeps.RACE)
        assert code == 0
        return folder / "race", text

    return run_once("sweep-race", make)
