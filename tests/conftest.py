"""Shared fixtures. ``tests/reference.py`` is the independent reference (no dockjax code)."""

from __future__ import annotations

import os
import pathlib
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


# Test processes (both xdist workers) and the CLI subprocesses of the tests share JAX's
# persistent compilation cache, so a computation compiled in one is reused by the others
# (tests that use the same shapes are aligned on purpose: e.g. the compare.py test and the
# refine tests). Test-only; the library never sets it.
CACHE = ROOT / ".pytest-jax-cache"
os.environ.setdefault("DOCKJAX_CACHE", str(CACHE))
os.environ.setdefault("DOCKJAX_FRONTS", str(CACHE / "fronts"))  # best-known fronts of the sweep tests


def pytest_configure(config):
    import jax

    CACHE.mkdir(exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(CACHE))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)


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
