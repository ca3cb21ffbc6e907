"""Hyper-parameter importance of a study (dockjax.sweep.importance): on score matrices whose
answer is known by construction (which parameter the scores depend on), and in a study's
report."""

from __future__ import annotations

import numpy as np
import pytest

from dockjax import sweep
from dockjax.sweep.importance import importances, varied_parameters


def _grid(seeds: int = 8, **kw):
    params = [sweep.ParamSpec("rho", "imocs", values=(0.1, 0.3, 0.5, 0.7, 0.9)),
              sweep.ParamSpec("alpha_max", "imocs", values=(0.1, 1.0, 3.0, 10.0, 30.0))]
    return sweep.make_config(algorithms=("imocs",), params=params, pop=(8,), iters=(3,), seeds=seeds, chunk=2,
                             reference="pilot", **kw)[0]


def _by(imp, indicator):
    return {i.parameter: i for i in imp if i.indicator == indicator}


def test_the_parameter_the_scores_depend_on_is_the_important_one():
    cfg = _grid()
    rho = np.array([s.value("rho") for s in cfg.settings])
    alpha = np.array([s.value("alpha_max") for s in cfg.settings])
    for depends, on in ((rho, "rho"), (np.log(alpha), "alpha_max")):
        hv = -(depends - depends.mean()) ** 2  # best in the middle of the grid
        hv = np.repeat(hv[:, None], cfg.seeds, 1) + np.linspace(-1e-9, 1e-9, cfg.seeds)  # seeds agree
        imp = importances(cfg, {"HV": hv, "IGD+": -hv}, resamples=20)
        other = "alpha_max" if on == "rho" else "rho"
        for indicator in ("HV", "IGD+"):
            got = _by(imp, indicator)
            assert got[on].value > 0.9 and got[other].value < 0.1, (on, indicator, got)
            assert got[on].value + got[other].value == pytest.approx(1.0)
            assert got[on].low > 0.9  # every resample agrees: the seeds do not disagree


def test_identical_blocks_give_a_zero_width_interval_and_missing_runs_are_left_out():
    cfg = _grid(seeds=6)
    rho = np.array([s.value("rho") for s in cfg.settings])
    hv = np.repeat((rho * (1 - rho))[:, None], 6, 1)
    hv[3, 4:] = np.nan  # a setting dropped by a race after four seeds
    imp = importances(cfg, {"HV": hv, "IGD+": -hv}, resamples=10)
    assert {i.blocks for i in imp} == {4}
    for i in imp:
        assert i.low == pytest.approx(i.value) and i.high == pytest.approx(i.value)


def test_noisy_scores_give_intervals_and_nothing_without_two_varied_parameters():
    cfg = _grid(seeds=10)
    rng = np.random.default_rng(0)
    hv = rng.normal(0.0, 1.0, (len(cfg.settings), 10))
    imp = importances(cfg, {"HV": hv, "IGD+": -hv}, resamples=30, seed=1)
    assert imp == importances(cfg, {"HV": hv, "IGD+": -hv}, resamples=30, seed=1)  # seeded
    for i in imp:
        assert 0.0 <= i.low <= i.high <= 1.0 and i.high - i.low > 0.05
    one = sweep.make_config(algorithms=("imocs",), params=[sweep.ParamSpec("rho", "imocs", values=(0.3, 0.5, 0.7))],
                            pop=(8,), iters=(3,), seeds=2, chunk=2, reference="pilot")[0]
    assert varied_parameters(one, range(3)) == ["rho"]
    assert importances(one, {"HV": np.zeros((3, 2)), "IGD+": np.zeros((3, 2))}) == []
    pops = sweep.make_config(algorithms=("imocs",), params=[sweep.ParamSpec("rho", "imocs", values=(0.3, 0.5))],
                             pop=(8, 16), iters=(3,), seeds=2, chunk=2, reference="pilot")[0]
    assert varied_parameters(pops, range(4)) == ["rho", "pop"]


def test_two_interacting_parameters_share_the_importance():
    """A planted interaction: the score is high only where ρ and α_max are both at one end of
    the grid, so neither alone decides and each carries a large share of the importance
    (0.40 and 0.60: ρ's grid is linear, α_max's logarithmic)."""
    cfg = _grid()
    rho = np.array([s.value("rho") for s in cfg.settings])
    alpha = np.array([s.value("alpha_max") for s in cfg.settings])
    hv = np.where((rho >= 0.7) & (alpha >= 10.0), 1.0, 0.0)
    hv = np.repeat(hv[:, None], cfg.seeds, 1) + np.linspace(-1e-9, 1e-9, cfg.seeds)
    got = _by(importances(cfg, {"HV": hv, "IGD+": -hv}, resamples=20), "HV")
    for name in ("rho", "alpha_max"):  # neither near 0 nor near 1, and established by every resample
        assert 0.3 < got[name].value < 0.7 and got[name].low > 0.25, got
