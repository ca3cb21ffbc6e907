"""The ablation path from an algorithm's defaults to a study's best setting: which of the
changed hyper-parameters buys the gain, and in which order.

The path starts at the best setting's algorithm, population and iteration count with every
hyper-parameter the best names at the algorithm's default (:func:`default_of`), and takes
one step per hyper-parameter whose best value differs from its default: at each step every
remaining parameter is set, one at a time, to its best value (the *candidates*), the
current setting and its candidates run the study's seeds (on its instances, if any) as a
study of their own in ``ablation/step-<k>/`` (:func:`run_ablation`: its own chunks,
resumption and report), and the candidate with the highest median HV becomes the current
setting. Each step records the parameter changed, the median HV before and after, and the
two-sided Wilcoxon signed-rank test (SciPy) of the chosen candidate against the current
setting on the blocks (seeds, or (instance, seed) pairs), paired; :func:`ablation_section`
puts the path in the main report with its figure. A study run again resumes every step's
study and takes the same path.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.stats import wilcoxon

from .. import algorithms, plots
from .config import SweepConfig, blocks_of
from .design import Setting, symbol
from .report import Study, best_setting, load_study, markdown_table, report
from .resume import prepare_folder, run_sweep

__all__ = ["ABLATION_FOLDER", "Step", "default_of", "ablation_steps", "run_ablation", "ablation_section"]

ABLATION_FOLDER = "ablation"
"""The subfolder of a study folder that holds the studies of its ablation path."""


@dataclass(frozen=True)
class Step:
    """One step of the path: ``parameter`` set from ``old`` to ``new``; the median HV of the
    setting before (``hv_before``) and after (``hv_after``) over ``blocks`` paired blocks,
    and the Wilcoxon signed-rank p-value of the change (NaN when every pair ties)."""

    parameter: str
    old: float
    new: float
    before: Setting
    after: Setting
    hv_before: float
    hv_after: float
    p: float
    blocks: int
    hv_runs_before: np.ndarray
    hv_runs_after: np.ndarray


def default_of(best: Setting) -> Setting:
    """``best`` with every hyper-parameter it names at its algorithm's default."""
    defaults = algorithms.get(best.algorithm).Params()
    return dataclasses.replace(best, params=tuple((k, type(v)(getattr(defaults, k))) for k, v in best.params))


def _with(setting: Setting, name: str, value) -> Setting:
    return dataclasses.replace(setting, params=tuple(sorted({**dict(setting.params), name: value}.items())))


def _hv_by_block(study: Study, setting: Setting) -> np.ndarray:
    """The setting's HV per block of ``study`` (NaN where missing)."""
    i = study.cfg.settings.index(setting)
    out = np.full(study.cfg.n_blocks, np.nan)
    sel = study.cols["setting"] == i
    out[blocks_of(study.cfg, {k: v[sel] for k, v in study.cols.items() if k in ("seed", "instance")})] = \
        study.cols["HV"][sel]
    return out


def ablation_steps(best: Setting, evaluate: Callable[[int, Setting, list[Setting]], tuple[np.ndarray, list]]
                   ) -> list[Step]:
    """The path from :func:`default_of` ``best`` to ``best`` (module docstring), whatever
    scores the settings: ``evaluate(k, current, candidates)`` → the current setting's HV
    per block (blocks,) and each candidate's (same blocks; NaN where missing), for step k."""
    current = default_of(best)
    todo = [name for name, v in best.params if current.value(name) != v]
    steps: list[Step] = []
    k = 0
    while todo:
        candidates = [_with(current, name, best.value(name)) for name in todo]
        base, runs = evaluate(k, current, candidates)
        base, runs = np.asarray(base, np.float64), [np.asarray(r, np.float64) for r in runs]
        j = int(np.argmax([np.nanmedian(r) for r in runs]))
        pair = np.isfinite(base) & np.isfinite(runs[j])
        diff = runs[j][pair] - base[pair]
        p = float(wilcoxon(runs[j][pair], base[pair]).pvalue) if np.any(diff != 0) else math.nan
        name = todo[j]
        steps.append(Step(name, current.value(name), best.value(name), current, candidates[j],
                          float(np.nanmedian(base)), float(np.nanmedian(runs[j])), p, int(pair.sum()),
                          base[pair], runs[j][pair]))
        current, todo, k = candidates[j], todo[:j] + todo[j + 1:], k + 1
    return steps


def run_ablation(cfg: SweepConfig, out: Path, *, top: int = 10, log: Callable[[str], None] = print,
                 **options) -> list[Step]:
    """Run (or resume) the ablation path of the finished study in ``out`` (module
    docstring): :func:`ablation_steps` with each step's settings run as a study in
    ``out/ablation/step-<k>``, reported. Returns the steps (none when the best setting is
    the default)."""
    index = best_setting(load_study(out).summary)
    if index is None:
        raise RuntimeError("no setting has a complete set of scores: there is no best setting to ablate")
    best = cfg.settings[index]

    def evaluate(k: int, current: Setting, candidates: list[Setting]):
        if k == 0:
            log(f"ablation: from the defaults to {best.label}")
        scfg = dataclasses.replace(cfg, settings=(current, *candidates), race=None, test_instances=())
        folder = Path(out) / ABLATION_FOLDER / f"step-{k}"
        prepare_folder(folder, scfg)
        log(f"ablation step {k}: {len(candidates)} candidate(s) from {current.label}")
        run_sweep(scfg, folder, log=log, **options)
        report(folder, top=top, log=lambda _: None)
        step_study = load_study(folder)
        return _hv_by_block(step_study, current), [_hv_by_block(step_study, c) for c in candidates]

    return ablation_steps(best, evaluate)


def ablation_section(steps: list[Step]):
    """A report extension (``(study, folder, log) -> (lines, files)``) giving the main
    report the ``Ablation path`` section of ``steps`` (:func:`run_ablation`) and its figure."""
    return lambda study, folder, log: _section(steps, study, folder)


def _section(steps: list[Step], study: Study, folder: Path) -> tuple[list[str], list[Path]]:
    if not steps:
        return ["## Ablation path", "", "The best setting is the algorithm's default: there is no path.", ""], []
    alg = steps[0].before.algorithm
    lines = ["## Ablation path", "",
             f"From {alg}'s defaults to the best setting, one hyper-parameter a step (the one whose change gives the "
             f"highest median HV among those left), each step a study of the current setting and its candidates in "
             f"`{ABLATION_FOLDER}/step-<k>/` on the same seeds{' and instances' if study.cfg.instances else ''}. "
             "p: two-sided Wilcoxon signed-rank test of the step, paired by block.", ""]
    body = [[str(k), symbol(alg, s.parameter), f"{s.old:g} → {s.new:g}", f"{s.hv_before:.4f}", f"{s.hv_after:.4f}",
             f"{s.hv_after - s.hv_before:+.4f}", "–" if math.isnan(s.p) else f"{s.p:.3g}", str(s.blocks)]
            for k, s in enumerate(steps)]
    lines += markdown_table(["step", "parameter", "value", "HV before", "HV after", "change", "p", "blocks"], body)
    x = np.arange(len(steps) + 1, dtype=float)
    runs = [steps[0].hv_runs_before] + [s.hv_runs_after for s in steps]
    data = {"median HV along the path": (x, np.array([np.median(r) for r in runs]),
                                         np.array([np.percentile(r, [25, 75]) for r in runs]))}
    path = plots.plot_median_iqr(data, Path(folder) / "ablation.png",
                                 xlabel="step (0: defaults; then " + ", ".join(symbol(alg, s.parameter) for s in steps)
                                 + ")", ylabel="hypervolume (median, bar = IQR)",
                                 title="ablation path from the defaults to the best setting")
    lines += ["", f"![ablation]({path.name})", ""]
    return lines, [path]
