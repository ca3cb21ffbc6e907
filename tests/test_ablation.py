"""The ablation path of a study (``dockjax sweep --ablation``, dockjax.sweep.ablation),
checked against each step's own runs.csv: the chosen candidate is the one with the highest
median HV there, and each step's p-value is SciPy's Wilcoxon signed-rank test on its runs
paired by seed. The tests' tiny study (tests/sweeps.py), whose best differs from IMOCS's
defaults (ρ = 0.4, α_max = 0.1) in both parameters."""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest
from scipy.stats import wilcoxon

from dockjax.sweep.ablation import ablation_steps, default_of
from dockjax.sweep.design import Setting
from tests import sweeps as S

ARGV = ["--rho", "0.3", "0.6", "--alpha-max", "0.3", "1", "--ablation"]


def _rows(path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def ablated(run_once):
    def make(folder):
        out = folder / "study"
        code, text = S.run(out, S.TINY, *ARGV)
        return code, text, out

    return run_once("ablation-study", make)


def _hv(rows, params: str) -> dict[int, float]:
    return {int(r["seed"]): float(r["HV"]) for r in rows if r["params"] == params}


def test_each_step_takes_the_best_candidate_and_the_path_ends_at_the_best_setting(ablated):
    code, text, out = ablated
    assert code == 0, text
    best = next(r["params"] for r in _rows(out / "summary.csv") if r["status"] == "best")
    steps = sorted((out / "ablation").iterdir())
    table = (out / "report.md").read_text()
    rows_md = [line for line in table[table.index("## Ablation path"):].splitlines() if re.match(r"\| \d+ \|", line)]
    assert len(steps) == len(rows_md) >= 1
    current = "alpha_max=0.1 rho=0.4"  # the defaults, in runs.csv's form
    for k, folder in enumerate(steps):
        rows = _rows(folder / "runs.csv")
        settings = {r["params"] for r in rows}
        assert current in settings
        candidates = sorted(settings - {current})
        medians = {c: np.median(list(_hv(rows, c).values())) for c in candidates}
        chosen = max(candidates, key=lambda c: medians[c])
        before, after = _hv(rows, current), _hv(rows, chosen)
        seeds = sorted(before)
        cells = [c.strip() for c in rows_md[k].strip("|").split("|")]
        assert float(cells[3]) == pytest.approx(np.median(list(before.values())), abs=5e-5)
        assert float(cells[4]) == pytest.approx(medians[chosen], abs=5e-5)
        a, b = np.array([after[s] for s in seeds]), np.array([before[s] for s in seeds])
        if np.any(a != b):
            assert float(cells[6]) == pytest.approx(wilcoxon(a, b).pvalue, rel=2e-3)
        current = chosen
    assert current == best


def test_the_path_resumes_without_computing_anything(ablated):
    _, _, out = ablated
    code, said = S.run(out, S.TINY, *ARGV)
    steps = len(list((out / "ablation").iterdir()))
    assert code == 0 and said.count("chunks already done") == 1 + steps, said


def _planted(response, blocks: int = 12, noise: float = 1e-3):
    """An ``evaluate`` for :func:`ablation_steps` scoring each setting by ``response(rho,
    alpha_max)`` plus seeded noise per block (the same noise for every setting of a block)."""
    shared = np.random.default_rng(0).normal(0.0, noise, blocks)
    own = np.random.default_rng(1)

    def score(s):
        return response(s.value("rho"), s.value("alpha_max")) + shared + own.normal(0.0, noise / 10, blocks)

    return lambda k, current, candidates: (score(current), [score(c) for c in candidates])


BEST = Setting("imocs", 8, 3, (("alpha_max", 1.0), ("p_a", 0.25), ("rho", 0.6)))
"""Differs from IMOCS's defaults (α_max 0.1, ρ 0.4) in two parameters; p_a is at its default."""


def test_when_one_parameter_matters_the_path_takes_it_first_and_only_its_step_counts():
    steps = ablation_steps(BEST, _planted(lambda rho, alpha: 0.5 * rho))
    assert [s.parameter for s in steps] == ["rho", "alpha_max"]
    assert (steps[0].old, steps[0].new) == (0.4, 0.6)
    assert steps[0].hv_after - steps[0].hv_before == pytest.approx(0.1, abs=2e-3) and steps[0].p < 0.01
    assert abs(steps[1].hv_after - steps[1].hv_before) < 2e-3
    assert steps[-1].after == BEST and steps[0].before.value("p_a") == 0.25


def test_when_two_parameters_interact_the_gain_comes_at_the_second_step():
    both = lambda rho, alpha: 0.1 * (rho == 0.6 and alpha == 1.0)  # noqa: E731 - only the pair helps
    steps = ablation_steps(BEST, _planted(both))
    assert len(steps) == 2
    assert abs(steps[0].hv_after - steps[0].hv_before) < 2e-3
    assert steps[1].hv_after - steps[1].hv_before == pytest.approx(0.1, abs=2e-3) and steps[1].p < 0.01
    assert ablation_steps(default_of(BEST), _planted(both)) == []  # the defaults: no path
