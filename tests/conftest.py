"""Shared fixtures. ``tests/reference.py`` is the independent reference (no dockjax code)."""

from __future__ import annotations

import pathlib
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


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
