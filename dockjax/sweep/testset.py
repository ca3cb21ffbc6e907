"""A held-out test set: does the study's answer hold on moves it was not tuned on?

After a study (its *training* instances, or the preset's move) the best setting and every
setting tied with it (the *elites*, :func:`elites`) run the same seeds on the test
instances (``--test-instances``), as a study of their own in the folder's ``test/``
subfolder (:func:`test_config`, :func:`run_test_set`): its own references (one per test
instance), chunks, resumption and report. The main report then compares training and
test (:func:`test_section`): each elite's median HV and IGD+ on both, their ranks, Kendall's
τ between the two orders, and whether the training's best is still the best or tied with
it on the test instances — whether the ranking held.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.stats import kendalltau

from .. import plots
from .config import SweepConfig
from .report import Study, Summary, load_study, markdown_table, report
from .resume import prepare_folder, run_sweep

__all__ = ["TEST_FOLDER", "elites", "test_config", "run_test_set", "test_section"]

TEST_FOLDER = "test"
"""The subfolder of a study folder that holds its test-set study."""


def elites(summary: Summary) -> list[int]:
    """The settings that run on the test set: the best by median HV and every finalist tied
    with it (not significantly worse), in the order of the study's settings."""
    c = summary.comparison
    if c is None:
        return []
    idx = np.flatnonzero(summary.finalists)
    return sorted(int(idx[j]) for j in range(len(idx)) if j == c.best or c.tied[j])


def test_config(cfg: SweepConfig, chosen: list[int]) -> SweepConfig:
    """The test-set study of ``cfg``: the ``chosen`` settings, the same seeds, chunk size,
    reference definition, devices and driver, on the test instances; no race."""
    return dataclasses.replace(cfg, settings=tuple(cfg.settings[i] for i in chosen), instances=cfg.test_instances,
                               test_instances=(), race=None)


def run_test_set(cfg: SweepConfig, out: Path, *, top: int = 10, log: Callable[[str], None] = print,
                 **options) -> Path:
    """Run (or resume) the test-set study of the finished study in ``out`` and report it:
    its elites on ``cfg.test_instances`` in ``out/test`` (``options``: those of
    :func:`dockjax.sweep.run_sweep`). Returns the test study's folder."""
    study = load_study(out)
    chosen = elites(study.summary)
    if not chosen:
        raise RuntimeError("no setting has a complete set of scores: there is nothing to test")
    tcfg = test_config(cfg, chosen)
    folder = Path(out) / TEST_FOLDER
    prepare_folder(folder, tcfg)
    log(f"test set: {len(chosen)} setting(s) (the best and those tied with it) on {len(cfg.test_instances)} held-out "
        f"instance(s), {cfg.seeds} seeds each, in {folder}")
    run_sweep(tcfg, folder, log=log, **options)
    report(folder, top=top, log=log)
    return folder


def _medians(study: Study, settings: list, column: str) -> np.ndarray:
    cols = study.cols
    out = []
    for s in settings:
        i = study.cfg.settings.index(s)
        v = cols[column][(cols["setting"] == i) & np.isfinite(cols[column])]
        out.append(float(np.median(v)) if v.size else math.nan)
    return np.array(out)


def test_section(study: Study, folder: Path, log: Callable[[str], None]) -> tuple[list[str], list[Path]]:
    """The main report's ``Test set`` section and its figure (a report extension): training
    against test medians of HV and IGD+ per elite, ranks, Kendall's τ and the verdict."""
    test = load_study(Path(study.out) / TEST_FOLDER)
    settings = list(test.cfg.settings)
    train_hv, test_hv = _medians(study, settings, "HV"), _medians(test, settings, "HV")
    train_ig, test_ig = _medians(study, settings, "IGD+"), _medians(test, settings, "IGD+")
    rank = lambda v: np.argsort(np.argsort(-v)) + 1  # noqa: E731 - 1 = the highest median HV
    r_train, r_test = rank(train_hv), rank(test_hv)
    best = int(np.argmax(train_hv))
    status = test.summary.rows[best]["status"]
    held = status in ("best", "tied")
    lines = ["## Test set", "",
             f"The best setting and the {len(settings) - 1} tied with it on the training "
             f"{'instances' if study.cfg.instances else 'move'} ran the same {study.cfg.seeds} seeds on "
             f"{len(study.cfg.test_instances)} held-out instance(s) (the study in `{TEST_FOLDER}/`, each instance "
             "scored against its own reference).", ""]
    if len(settings) >= 3:
        tau = kendalltau(train_hv, test_hv)
        lines.append(f"Kendall's τ between the training and test orders by median HV: {tau.statistic:.2f} "
                     f"(p = {tau.pvalue:.3g}, {len(settings)} settings).")
    lines.append(f"The training's best, {settings[best].label}, is **{status}** on the test instances: the "
                 + ("ranking held." if held else "ranking did not hold (it is significantly worse there than the "
                    "test's best)."))
    lines.append("")
    body = [[s.label, f"{train_hv[k]:.4f}", f"{test_hv[k]:.4f}", f"{train_ig[k]:.4f}", f"{test_ig[k]:.4f}",
             str(r_train[k]), str(r_test[k]), test.summary.rows[k]["status"]] for k, s in enumerate(settings)]
    lines += markdown_table(["setting", "HV train", "HV test", "IGD+ train", "IGD+ test", "rank train", "rank test",
                             "on the test set"], body) + [""]
    data = {}
    for k, s in enumerate(settings):
        quart = []
        for st in (study, test):
            i = st.cfg.settings.index(s)
            v = st.cols["HV"][st.cols["setting"] == i]
            quart.append(np.percentile(v, [25, 75]) if v.size else [math.nan] * 2)
        data[s.label] = (np.array([0.0, 1.0]), np.array([train_hv[k], test_hv[k]]), np.array(quart))
    path = plots.plot_median_iqr(data, Path(folder) / "hv_train_test.png", xlabel="0: training, 1: test",
                                 ylabel="hypervolume (median, bar = IQR)",
                                 title="hypervolume on the training and the test instances")
    lines += [f"![hv_train_test]({path.name})", ""]
    log(f"test set: {settings[best].label} is {status} on the held-out instances")
    return lines, [path]
