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
