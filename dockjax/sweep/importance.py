"""Which hyper-parameter matters: the importance of each hyper-parameter a study varies, per
indicator, with bootstrap intervals over the study's blocks.

For each algorithm whose settings vary at least two hyper-parameters (``Params`` fields,
and the population size and iteration count when they vary), every setting is one trial
whose value is its median indicator over the blocks all those settings share (seeds, or
(instance, seed) pairs); the importance of each hyper-parameter is PED-ANOVA's (Watanabe et
al. 2023, Optuna's default importance evaluator,
:class:`optuna.importance.PedAnovaImportanceEvaluator`, its top 10 % of the settings, at least
:data:`TOP_SETTINGS` of them, against the whole design, ``evaluate_on_local=False``): how much
the parameter's distribution among the top settings differs from its distribution over all
of them, normalised to sum to 1 over the parameters. (Evaluated locally, inside the top
region only, as is Optuna's default, the answer on a study's small grid follows the noise:
on a 5 × 5 grid whose HV depends on ρ alone, with noise of 1 % of the HV range, α_max came
out more important than ρ.) The interval resamples the blocks
with replacement (:data:`RESAMPLES` times, seeded), recomputes every setting's median and
the importances, and takes the 2.5 and 97.5 percentiles: an importance whose interval
reaches 0 is not established by the study's seeds.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import optuna
from optuna.distributions import FloatDistribution, IntDistribution
from optuna.importance import PedAnovaImportanceEvaluator, get_param_importances

from .config import SweepConfig

__all__ = ["Importance", "RESAMPLES", "SETTING_FIELDS", "varied_parameters", "importances"]

TOP_QUANTILE = 0.1
"""PED-ANOVA's top quantile (Optuna's default), raised where needed so that the top holds
:data:`TOP_SETTINGS` settings."""
TOP_SETTINGS = 3
"""Fewest settings in PED-ANOVA's top: a 3 × 3 grid's top 10 % is one setting, whose
parameters then all look equally important (0.5 each, whatever the scores)."""
MIN_SETTINGS = 2 * TOP_SETTINGS
"""Fewest settings of one algorithm whose importances are computed (the top must be a
proper part of them)."""
SETTING_FIELDS = ("pop", "iterations", "refine_steps")
"""Hyper-parameters of a setting that are not ``Params`` fields (all integers)."""
RESAMPLES = 100
"""Bootstrap resamples of the blocks behind each importance interval."""
INDICATORS = (("HV", "maximize"), ("IGD+", "minimize"))
"""The indicators whose importances are reported, with the direction that is better."""


@dataclass(frozen=True)
class Importance:
    """One hyper-parameter's importance for one algorithm and indicator: ``value`` (0–1,
    summing to 1 over the algorithm's varied parameters) and its bootstrap interval
    ``[low, high]`` over ``blocks`` blocks."""

    algorithm: str
    indicator: str
    parameter: str
    value: float
    low: float
    high: float
    blocks: int


def _value(setting, name: str) -> float:
    return {"pop": setting.pop, "iterations": setting.iters, "refine_steps": setting.refine_steps}.get(
        name, setting.value(name))


def varied_parameters(cfg: SweepConfig, members: Sequence[int]) -> list[str]:
    """The hyper-parameters that take at least two values among the settings ``members``
    (``Params`` fields, then ``pop``, ``iterations`` and ``refine_steps``, the memetic finish)."""
    names = sorted({k for i in members for k, _ in cfg.settings[i].params}) + list(SETTING_FIELDS)
    out = []
    for name in names:
        values = {_value(cfg.settings[i], name) for i in members}
        if len(values) > 1 and not any(isinstance(v, float) and math.isnan(v) for v in values):
            out.append(name)
    return out


def _distribution(values: np.ndarray, integer: bool):
    lo, hi = float(values.min()), float(values.max())
    if integer:
        return IntDistribution(int(lo), int(hi), log=lo > 0 and hi / lo >= 10)
    return FloatDistribution(lo, hi, log=lo > 0 and hi / lo >= 10)


def _ped_anova(params: dict[str, np.ndarray], values: np.ndarray, direction: str,
               integer: dict[str, bool]) -> dict[str, float] | None:
    """PED-ANOVA importances of ``params`` (name → one value per trial) for the trials'
    ``values``, through an in-memory Optuna study (Optuna's log quietened meanwhile); None
    when they are not informative (Optuna warns that the top trials are all of them, e.g.
    when the values tie)."""
    dists = {k: _distribution(v, integer[k]) for k, v in params.items()}
    level = optuna.logging.get_verbosity()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        study = optuna.create_study(direction=direction)
        for t in range(len(values)):
            point = {k: (int(v[t]) if integer[k] else float(v[t])) for k, v in params.items()}
            study.add_trial(optuna.trial.create_trial(params=point, distributions=dists, value=float(values[t])))
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            top = max(TOP_QUANTILE, TOP_SETTINGS / len(values))
            out = get_param_importances(study, evaluator=PedAnovaImportanceEvaluator(
                target_quantile=top, evaluate_on_local=False))
    finally:
        optuna.logging.set_verbosity(level)
    if any("select the same set of trials" in str(w.message) for w in said):
        return None
    total = sum(out.values())
    return {k: (out.get(k, 0.0) / total if total > 0 else 0.0) for k in params}


def importances(cfg: SweepConfig, matrices: dict[str, np.ndarray], *, resamples: int = RESAMPLES,
                seed: int = 0) -> list[Importance]:
    """The importances of every algorithm's varied hyper-parameters (module docstring).
    ``matrices``: indicator name → (settings, blocks) scores, NaN where a run is missing (a
    race's dropped settings); only the blocks that all of an algorithm's settings have
    count. Algorithms with fewer than two varied parameters, :data:`MIN_SETTINGS` settings
    or two common blocks, and indicators whose importances are not informative (every setting ties), are
    left out; an interval is taken over the informative resamples."""
    out: list[Importance] = []
    rng = np.random.default_rng(seed)
    for algorithm in cfg.algorithms:
        members = [i for i, s in enumerate(cfg.settings) if s.algorithm == algorithm]
        names = varied_parameters(cfg, members)
        if len(names) < 2 or len(members) < MIN_SETTINGS:
            continue
        params = {k: np.array([_value(cfg.settings[i], k) for i in members], np.float64) for k in names}
        integer = {k: k in SETTING_FIELDS or isinstance(_value(cfg.settings[members[0]], k), int)
                   for k in names}
        common = np.flatnonzero(np.all([np.isfinite(np.asarray(matrices[ind], np.float64)[members]).all(axis=0)
                                        for ind, _ in INDICATORS], axis=0))
        if common.size < 2:
            continue
        draws = rng.integers(0, common.size, (resamples, common.size))  # the same blocks for every indicator
        for indicator, direction in INDICATORS:
            M = np.asarray(matrices[indicator], np.float64)[members][:, common]
            point = _ped_anova(params, np.median(M, axis=1), direction, integer)
            if point is None:
                continue
            boot = [_ped_anova(params, np.median(M[:, d], axis=1), direction, integer) for d in draws]
            boot = np.array([[b[k] for k in names] for b in boot if b is not None]).reshape(-1, len(names))
            lo, hi = (np.percentile(boot, [2.5, 97.5], axis=0) if len(boot)
                      else np.full((2, len(names)), np.nan))
            out += [Importance(algorithm, indicator, k, point[k], float(lo[j]), float(hi[j]), int(common.size))
                    for j, k in enumerate(names)]
    return out
