"""The report of a finished sweep folder: which settings are as good as the best, and how
sure that is.

Writes ``runs.csv`` (one row per run), ``fronts.npz``, ``summary.csv`` and ``summary.md``
(per setting: the median and a bootstrap 95 % interval of HV and IGD+, the other
indicators' medians, the mean Friedman rank, the Wilcoxon p-value against the best with
Holm's correction, the Vargha–Delaney A₁₂ of the best over it, and whether it is tied with
the best; for a race, the round it was eliminated in), ``report.md`` (the verdict, the
table, the race's rounds and every figure) and the figures: anytime hypervolume against
evaluations, the median attainment surfaces of the best and the default setting with their
EAF difference (moocore), heat maps over two hyper-parameters, hypervolume against
population size, and the fronts of the best and the worst setting.

The verdict never crowns a winner the data cannot distinguish: the best setting by median
HV is named together with every setting not significantly worse than it.

A report may be extended (``report(..., extensions=[...])``): an extension receives the
:class:`Study` the report was made from and returns lines for ``report.md`` and the files
it wrote (``dockjax compare`` adds the paper's tables this way, :mod:`.paper`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import moocore
import numpy as np
from scipy.stats import rankdata

from .. import plots, stats
from ..io import atomic_savez, atomic_write_text, write_set
from .config import COLUMNS, INDICATOR_COLUMNS, SweepConfig, blocks_of, round_seeds
from .design import symbol
from .files import finished_chunks, load_npz, reference_path
from .importance import SETTING_FIELDS, Importance, importances
from .race import replay

__all__ = ["Study", "Summary", "load_table", "load_config", "load_study", "summarise", "report", "write_table",
           "markdown_table"]

TOP_VIEWS = 4
"""Settings drawn in the anytime view (the leading ones by median HV, and the default)."""


def _fmt(v) -> str:
    if isinstance(v, (str, np.str_)):
        return str(v)
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))


def load_config(out: Path) -> SweepConfig:
    """The configuration stored in ``out/config.json``."""
    return SweepConfig.from_identity(json.loads((Path(out) / "config.json").read_text())["identity"])


def load_table(out: Path, cfg: SweepConfig | None = None
               ) -> tuple[dict[str, np.ndarray], list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """The runs of the study in ``out`` (its configuration ``cfg``, default the folder's),
    from the chunk files of its plan only (:func:`dockjax.sweep.files.finished_chunks`:
    a stray or foreign file is not read), sorted by (setting, instance, seed): the columns, each
    run's front F (k, 2) and its trajectories X (k, n_var), and each run's anytime
    hypervolume (iterations,). Raises RuntimeError when the study is not finished."""
    cfg = load_config(out) if cfg is None else cfg
    parts = [data for _, data in finished_chunks(cfg, Path(out))]
    keys = ("setting", "algorithm", "seed", *(("instance",) if cfg.instances else ()), "round", "chunk",
            *INDICATOR_COLUMNS, "T_min", "T_max", "jerk_min", "jerk_max", "wall_s")
    cols = {k: np.concatenate([p[k] for p in parts]) for k in keys}

    def split(name):
        return [p[name][a:b] for p in parts for a, b in zip(p["front_offsets"][:-1], p["front_offsets"][1:])]

    fronts, fronts_X = split("front_F"), split("front_X")
    history = [h for p in parts for h in p["history"]]
    order = np.lexsort((cols["seed"], cols.get("instance", cols["seed"]), cols["setting"]))
    return ({k: v[order] for k, v in cols.items()}, [fronts[i] for i in order], [fronts_X[i] for i in order],
            [history[i] for i in order])


def _matrix(cfg: SweepConfig, cols, column: str) -> np.ndarray:
    """``column`` as a (settings, blocks) matrix (:func:`dockjax.sweep.config.blocks_of`);
    NaN where a run is missing."""
    M = np.full((len(cfg.settings), cfg.n_blocks), np.nan)
    M[cols["setting"], blocks_of(cfg, cols)] = cols[column]
    return M


def best_setting(summary: "Summary") -> int | None:
    """Index of the best setting by median HV among the finalists (None when nothing
    could be compared)."""
    c = summary.comparison
    return None if c is None else int(np.flatnonzero(summary.finalists)[c.best])


def _blocks_word(cfg: SweepConfig, n: int) -> str:
    """``"12 seeds"``, or over instances ``"12 blocks (instance, seed)"``."""
    return f"{n} blocks (instance, seed)" if cfg.instances else f"{n} seeds"


def per_instance(study: "Study", settings: Sequence[int], column: str = "HV") -> np.ndarray:
    """Median of ``column`` per setting (rows, in the order of ``settings``) and instance
    (columns) of a study over instances: (len(settings), instances)."""
    cols = study.cols
    out = np.full((len(settings), study.cfg.n_instances), np.nan)
    for a, i in enumerate(settings):
        for k in range(study.cfg.n_instances):
            v = cols[column][(cols["setting"] == i) & (cols["instance"] == k)]
            v = v[np.isfinite(v)]
            out[a, k] = np.median(v) if v.size else np.nan
    return out


@dataclass
class Summary:
    """Per setting (rows in the order of ``cfg.settings``), the comparison of the finalists
    and the hyper-parameters' importances (:mod:`.importance`)."""

    rows: list[dict]
    finalists: np.ndarray
    comparison: stats.Comparison | None
    rounds: list[np.ndarray]
    importance: list[Importance]


@dataclass
class Study:
    """A finished sweep folder, loaded: what its report (and an extension) is made from.
    Runs are sorted by (setting, instance, seed): ``cols`` the table's columns, ``fronts`` /
    ``fronts_X`` each run's front (k, 2) and its trajectories (k, n_var), ``history`` each
    run's anytime hypervolume; ``ref`` the folder's reference (``reference.npz``; over
    instances the first instance's, which the figures of fronts show)."""

    out: Path
    cfg: SweepConfig
    cols: dict[str, np.ndarray]
    fronts: list[np.ndarray]
    fronts_X: list[np.ndarray]
    history: list[np.ndarray]
    ref: dict[str, np.ndarray]
    summary: Summary

    def runs_of(self, setting: int) -> np.ndarray:
        """Indices of the runs of one setting, by seed."""
        return np.flatnonzero(self.cols["setting"] == setting)


def load_study(out: Path) -> Study:
    """The folder's configuration, runs, reference and statistics (:func:`summarise`)."""
    out = Path(out)
    cfg = load_config(out)
    cols, fronts, fronts_X, history = load_table(out, cfg)
    ref = load_npz(reference_path(out, 0 if cfg.instances else -1))
    return Study(out, cfg, cols, fronts, fronts_X, history, ref, summarise(cfg, cols))


def summarise(cfg: SweepConfig, cols, alpha: float = 0.05) -> Summary:
    """The statistics of every setting (see the module docstring)."""
    hv, igdp = _matrix(cfg, cols, "HV"), _matrix(cfg, cols, "IGD+")
    rounds = [alive for _, alive in replay(cfg, hv)] if cfg.race else []
    finalists = rounds[-1] if rounds else np.isfinite(hv).any(axis=1)
    idx = np.flatnonzero(finalists)
    common = np.all(np.isfinite(hv[idx]), axis=0)
    comparison = stats.compare_to_best(hv[idx][:, common], alpha) if idx.size and common.any() else None
    ranks = np.full(len(cfg.settings), np.nan)
    if idx.size > 1 and common.sum() > 0:
        r = np.stack([rankdata(-hv[idx][:, s]) for s in np.flatnonzero(common)], axis=1)
        ranks[idx] = r.mean(axis=1)
    eliminated = np.full(len(cfg.settings), -1)
    for r, alive in enumerate(rounds):
        eliminated[(eliminated < 0) & ~alive] = r
    rows = []
    for i, s in enumerate(cfg.settings):
        v = hv[i][np.isfinite(hv[i])]
        if cfg.instances:  # intervals by resampling instances, each with its seeds
            med, lo, hi = stats.median_ci_clustered(hv[i].reshape(cfg.seeds, cfg.n_instances).T, seed=i)
            gmed, glo, ghi = stats.median_ci_clustered(igdp[i].reshape(cfg.seeds, cfg.n_instances).T, seed=i)
        else:
            med, lo, hi = stats.median_ci(v, seed=i)
            gmed, glo, ghi = stats.median_ci(igdp[i][np.isfinite(igdp[i])], seed=i)
        row = {"setting": i, "label": s.label, "algorithm": s.name, "pop": s.pop, "iterations": s.iters,
               "params": " ".join(f"{k}={v:g}" for k, v in s.params), "runs": int(v.size), "HV_median": med,
               "HV_ci_low": lo, "HV_ci_high": hi, "IGD+_median": gmed, "IGD+_ci_low": glo, "IGD+_ci_high": ghi}
        sel = cols["setting"] == i
        for ind in ("IGD", "GD", "SP", "ONVG"):
            x = cols[ind][sel].astype(float)
            row[f"{ind}_median"] = float(np.nanmedian(x)) if np.isfinite(x).any() else math.nan
        row["mean_rank"] = ranks[i]
        row.update(p_vs_best=math.nan, p_holm=math.nan, A12_best_over=math.nan, tied_with_best=False)
        if comparison is not None and finalists[i]:
            j = int(np.flatnonzero(idx == i)[0])
            row.update(p_vs_best=comparison.p[j], p_holm=comparison.p_holm[j], A12_best_over=comparison.a12[j],
                       tied_with_best=bool(comparison.tied[j]))
        row["status"] = ("best" if comparison is not None and finalists[i] and idx[comparison.best] == i
                         else "tied" if row["tied_with_best"] else
                         f"eliminated in round {eliminated[i]}" if eliminated[i] >= 0 else "worse")
        rows.append(row)
    return Summary(rows, finalists, comparison, rounds, importances(cfg, {"HV": hv, "IGD+": igdp}))


def _order(rows: list[dict]) -> list[dict]:
    rank = {"best": 0, "tied": 1, "worse": 2}
    return sorted(rows, key=lambda r: (rank.get(r["status"], 3), -np.nan_to_num(r["HV_median"], nan=-np.inf),
                                       r["setting"]))


def _verdict(cfg: SweepConfig, summary: Summary) -> list[str]:
    c = summary.comparison
    if c is None:
        return ["No setting has a complete set of scores: nothing can be compared."]
    idx = np.flatnonzero(summary.finalists)
    best = cfg.settings[idx[c.best]]
    tied = [cfg.settings[idx[j]] for j in np.flatnonzero(c.tied) if j != c.best]
    n_blocks = int(summary.rows[idx[c.best]]["runs"])
    fp = "n/a" if math.isnan(c.friedman_p) else f"{c.friedman_p:.3g}"
    lines = [f"Best by median HV: **{best.label}** (median {summary.rows[idx[c.best]]['HV_median']:.4f} over "
             f"{_blocks_word(cfg, n_blocks)}). Friedman test across the {len(idx)} compared settings: p = {fp}."]
    if len(tied) == len(idx) - 1 and tied:
        advice = ("A race with a larger seed budget (--seeds) may separate them." if cfg.race else
                  "Run more seeds or instances." if cfg.instances else "Run more seeds, or race them (--race).")
        lines.append(f"No setting is significantly worse than it at {_blocks_word(cfg, n_blocks)} (Wilcoxon "
                     f"signed-rank against the best, Holm's correction, α = {c.alpha:g}): all {len(idx)} are tied, "
                     f"and this study cannot name a winner. {advice}")
    elif tied:
        lines.append(f"{len(tied)} other setting(s) are not significantly worse (Wilcoxon signed-rank against the "
                     f"best, Holm's correction, α = {c.alpha:g}) and tie with it: "
                     + "; ".join(s.label for s in tied) + ".")
    else:
        lines.append(f"Every other compared setting is significantly worse (Wilcoxon signed-rank against the best, "
                     f"Holm's correction, α = {c.alpha:g}).")
    return lines


SUMMARY_COLUMNS = ("setting", "algorithm", "pop", "iterations", "params", "runs", "HV_median", "HV_ci_low",
                   "HV_ci_high", "IGD+_median", "IGD+_ci_low", "IGD+_ci_high", "IGD_median", "GD_median", "SP_median",
                   "ONVG_median", "mean_rank", "p_vs_best", "p_holm", "A12_best_over", "tied_with_best", "status")


def markdown_table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table: one line per row, cells already formatted."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + ["| " + " | ".join(r) + " |" for r in rows]


def write_table(rows: list[dict], columns: Sequence[str], path: Path) -> Path:
    """``rows`` as a CSV file (one line per row, the values of ``columns``; numbers written
    exactly: ``repr`` of floats), atomically."""
    lines = [",".join(columns)] + [",".join(_fmt(r[c]) for c in columns) for r in rows]
    return atomic_write_text(path, "\n".join(lines) + "\n")


def _num(v, spec: str) -> str:
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def _md_table(rows: list[dict], limit: int | None = None) -> list[str]:
    head = ["setting", "runs", "HV median [95 % CI]", "IGD+ median [95 % CI]", "mean rank", "p (Holm)",
            "A₁₂ of best", "verdict"]
    return markdown_table(head, [[
        r["label"], str(r["runs"]),
        f"{_num(r['HV_median'], '.4f')} [{_num(r['HV_ci_low'], '.4f')}, {_num(r['HV_ci_high'], '.4f')}]",
        f"{_num(r['IGD+_median'], '.4f')} [{_num(r['IGD+_ci_low'], '.4f')}, {_num(r['IGD+_ci_high'], '.4f')}]",
        _num(r["mean_rank"], ".2f"), _num(r["p_holm"], ".3g"), _num(r["A12_best_over"], ".2f"), r["status"]]
        for r in rows[:limit]])


def _figures(study: Study, out: Path) -> list[Path]:
    """The study's figures, written into ``out``."""
    cfg, cols, fronts, history, summary, ref = (study.cfg, study.cols, study.fronts, study.history, study.summary,
                                                study.ref)
    written: list[Path] = []
    rows = _order(summary.rows)
    ranked = [r["setting"] for r in rows if r["runs"]]
    # anytime hypervolume of the leading settings and the default
    default = next((i for i, s in enumerate(cfg.settings) if s.is_default() and summary.rows[i]["runs"]), None)
    shown = _leading(study, rows)
    # fronts are drawn in objective units: over instances, the first instance's runs only
    on_view = (cols["instance"] == 0) if cfg.instances else np.ones(len(cols["setting"]), bool)
    view = f" ({cfg.instances[0].name})" if cfg.instances else ""
    curves = {}
    for i in shown:
        sel = np.flatnonzero(cols["setting"] == i)
        H = np.stack([history[k] for k in sel])
        s = cfg.settings[i]
        curves[s.label + (" (default)" if i == default else "")] = (s.pop * (np.arange(H.shape[1]) + 2), H)
    written.append(plots.plot_anytime(curves, out / "anytime_hv.png", title="anytime hypervolume, median and IQR"))
    # median attainment surfaces of the best and the default (or the worst) setting
    best = ranked[0]
    other = default if default is not None and default != best else (ranked[-1] if len(ranked) > 1 else None)
    if other is not None:
        sets = {}
        for i in (best, other):
            runs = [fronts[k] for k in np.flatnonzero((cols["setting"] == i) & on_view) if len(fronts[k])]
            if runs:
                sets[i] = np.concatenate([np.column_stack([f, np.full(len(f), n + 1)]) for n, f in enumerate(runs)])
        if len(sets) == 2:
            a, b = sets[best], sets[other]
            surf = {i: moocore.eaf(sets[i][:, :2], sets[i][:, 2], percentiles=[50])[:, :2] for i in (best, other)}
            diff = moocore.eafdiff(a, b, rectangles=True)
            label = lambda i: cfg.settings[i].label + (" (default)" if i == default else "")  # noqa: E731
            written.append(plots.plot_eaf(surf[best], surf[other], diff, label(best), label(other),
                                          int(a[:, 2].max()), int(b[:, 2].max()), ref["front"], out / "eaf.png"))
    # heat maps over two hyper-parameters of one algorithm, population and iteration count
    groups: dict[tuple, list[int]] = {}
    for i, s in enumerate(cfg.settings):
        groups.setdefault((s.algorithm, s.pop, s.iters, tuple(k for k, _ in s.params)), []).append(i)
    for (algorithm, pop, iters, names), members in groups.items():
        if len(names) != 2 or len(members) < 2:
            continue
        xs = sorted({cfg.settings[i].value(names[1]) for i in members})
        ys = sorted({cfg.settings[i].value(names[0]) for i in members})
        if len(xs) * len(ys) != len(members):  # sampled, not a grid
            continue
        M = np.full((len(ys), len(xs)), np.nan)
        tied = np.zeros(M.shape, bool)
        best_cell = None
        for i in members:
            s = cfg.settings[i]
            cell = (ys.index(s.value(names[0])), xs.index(s.value(names[1])))
            M[cell] = summary.rows[i]["HV_median"]
            tied[cell] = summary.rows[i]["tied_with_best"]
            best_cell = cell if summary.rows[i]["status"] == "best" else best_cell
        sym = [symbol(algorithm, n) for n in names]
        written.append(plots.plot_heatmap(M, ys, xs, out / f"heatmap_hv_{algorithm}_pop{pop}_it{iters}.png",
                                          xlabel=sym[1], ylabel=sym[0], tied=tied, best=best_cell,
                                          title=f"{algorithm}: median HV, pop {pop}, {iters} iterations"))
    # HV against population size, one line per (algorithm, iterations, hyper-parameters)
    if len({s.pop for s in cfg.settings}) > 1:
        lines: dict[str, list[int]] = {}
        for i, s in enumerate(cfg.settings):
            if summary.rows[i]["runs"]:
                name = ", ".join([s.algorithm] + [f"{k}={v:g}" for k, v in s.params])
                lines.setdefault(name, []).append(i)
        data = {}
        for name, members in lines.items():
            members.sort(key=lambda i: cfg.settings[i].pop)
            hv = [cols["HV"][cols["setting"] == i] for i in members]
            data[name] = (np.array([cfg.settings[i].pop for i in members], float),
                          np.array([np.median(h) for h in hv]),
                          np.array([np.percentile(h, [25, 75]) for h in hv]).reshape(-1, 2))
        written.append(plots.plot_median_iqr(data, out / "hv_vs_pop.png", xlabel="population size",
                                             ylabel="hypervolume (median, bar = IQR)",
                                             title="hypervolume against population size"))
    worst = ranked[-1]
    groups_f = {f"{what}: {cfg.settings[i].label} (HV {summary.rows[i]['HV_median']:.3f})":
                [fronts[k] for k in np.flatnonzero((cols["setting"] == i) & on_view)]
                for i, what in ((best, "best"), (worst, "worst"))[: 1 if best == worst else 2]}
    written.append(plots.plot_front_groups(groups_f, ref["front"], out / "fronts_best_worst.png",
                                           reference_label="reference front (fixed at sweep start)",
                                           title="fronts of every seed, best and worst setting by median HV" + view))
    for algorithm in dict.fromkeys(i.algorithm for i in summary.importance):
        bars = {}
        for indicator in ("HV", "IGD+"):
            mine = [i for i in summary.importance if i.algorithm == algorithm and i.indicator == indicator]
            if mine:
                names = [_symbol(algorithm, i.parameter) for i in mine]
                bars[indicator] = (names, np.array([i.value for i in mine]), np.array([[i.low, i.high] for i in mine]))
        written.append(plots.plot_importance(bars, out / f"importance_{algorithm}.png",
                                             title=f"{algorithm}: hyper-parameter importance"))
    if cfg.instances:  # each leading setting's HV on every instance
        k = np.arange(cfg.n_instances, dtype=float)
        data = {}
        for i in shown:
            per = [cols["HV"][(cols["setting"] == i) & (cols["instance"] == j)] for j in range(cfg.n_instances)]
            data[cfg.settings[i].label] = (k, np.array([np.median(h) for h in per]),
                                           np.array([np.percentile(h, [25, 75]) for h in per]).reshape(-1, 2))
        written.append(plots.plot_median_iqr(data, out / "hv_per_instance.png", xlabel="instance (index)",
                                             ylabel="hypervolume (median, bar = IQR over seeds)",
                                             title="hypervolume per instance, leading settings"))
    return written


def _leading(study: Study, rows: list[dict]) -> list[int]:
    """The settings the anytime view and the per-instance view show: the leading ones by
    median HV (:data:`TOP_VIEWS`) and the default."""
    cfg, summary = study.cfg, study.summary
    ranked = [r["setting"] for r in rows if r["runs"]]
    default = next((i for i, s in enumerate(cfg.settings) if s.is_default() and summary.rows[i]["runs"]), None)
    return list(dict.fromkeys(ranked[:TOP_VIEWS] + ([default] if default is not None else [])))


def _symbol(algorithm: str, name: str) -> str:
    """A varied parameter's label: the paper's symbol of a ``Params`` field, else its name."""
    return name if name in SETTING_FIELDS else symbol(algorithm, name)


def _importance_section(study: Study) -> list[str]:
    """report.md's importance table: per algorithm, each varied hyper-parameter's importance
    for HV and IGD+ with its interval."""
    imp = study.summary.importance
    lines = ["## Hyper-parameter importance", "",
             "PED-ANOVA (Optuna's evaluator; the top 10 % of the settings, at least 3, against all of them), from "
             "each setting's median over the blocks all of an algorithm's settings share, with 95 % bootstrap "
             f"intervals resampling those blocks ({imp[0].blocks} for {imp[0].algorithm}). The importances of one "
             "algorithm and indicator sum to 1; one whose interval reaches 0 is not established by this study.", ""]
    body = []
    for algorithm in dict.fromkeys(i.algorithm for i in imp):
        mine = [i for i in imp if i.algorithm == algorithm]
        for name in dict.fromkeys(i.parameter for i in mine):
            cells = []
            for indicator in ("HV", "IGD+"):
                hit = [i for i in mine if i.parameter == name and i.indicator == indicator]
                cells.append(f"{hit[0].value:.2f} [{hit[0].low:.2f}, {hit[0].high:.2f}]" if hit else "–")
            body.append([algorithm, _symbol(algorithm, name), *cells])
    return lines + markdown_table(["algorithm", "hyper-parameter", "HV importance [95 % CI]",
                                   "IGD+ importance [95 % CI]"], body) + [""]


def _instance_section(study: Study, rows: list[dict]) -> list[str]:
    """report.md's per-instance table: the leading settings' median HV on each instance."""
    cfg = study.cfg
    shown = _leading(study, rows)
    M = per_instance(study, shown)
    lines = ["## Per instance", "", f"Median HV over the {cfg.seeds} seeds of each instance (normalised by the "
             "instance's own reference front), for the leading settings and the default:", ""]
    header = ["instance", *[cfg.settings[i].label for i in shown]]
    body = [[inst.name, *[_num(v, ".4f") for v in M[:, k]]] for k, inst in enumerate(cfg.instances)]
    return lines + markdown_table(header, body) + [""]


Extension = Callable[[Study, Path, Callable[[str], None]], tuple[list[str], list[Path]]]
"""A report extension: ``(study, folder, log) -> (lines of report.md, files written into
folder)``."""


def report(out: Path, *, top: int = 10, extensions: Sequence[Extension] = (),
           log: Callable[[str], None] = print) -> list[Path]:
    """Tables, statistics, ``report.md`` and the figures of a finished sweep folder, with
    the sections and files of ``extensions``, written as one set
    (:func:`dockjax.io.write_set`: an interrupted report leaves the previous one whole);
    prints the verdict and the leading rows. Returns the files written."""
    study = load_study(out)
    written = write_set(out, lambda stage: _report_files(study, stage, extensions, log))
    rows = _order(study.summary.rows)
    log("")
    for line in _verdict(study.cfg, study.summary):
        log(line.replace("**", ""))
    log(f"{'':>2}  {'setting':<46} {'runs':>4} {'HV median [95% CI]':>26} {'p (Holm)':>9} {'A12':>5}  verdict")
    for r in rows[:top]:
        p = "" if math.isnan(r["p_holm"]) else f"{r['p_holm']:.3g}"
        a = "" if math.isnan(r["A12_best_over"]) else f"{r['A12_best_over']:.2f}"
        ci = f"{r['HV_median']:.4f} [{r['HV_ci_low']:.4f}, {r['HV_ci_high']:.4f}]"
        log(f"{'':>2}  {r['label'][:46]:<46} {r['runs']:>4} {ci:>26} {p:>9} {a:>5}  {r['status']}")
    if len(rows) > top:
        log(f"    ... {len(rows) - top} more in {Path(out) / 'summary.csv'}")
    log(f"wrote {len(written)} files to {out}: {', '.join(p.name for p in written)}")
    return written


def _report_files(study: Study, folder: Path, extensions, log) -> list[Path]:
    """Every file of the report, written into ``folder``."""
    cfg, cols, fronts, ref, summary = study.cfg, study.cols, study.fronts, study.ref, study.summary
    written = []
    table = {**cols, "pop": np.array([cfg.settings[i].pop for i in cols["setting"]]),
             "iterations": np.array([cfg.settings[i].iters for i in cols["setting"]]),
             "params": np.array([" ".join(f"{k}={v:g}" for k, v in cfg.settings[i].params) for i in cols["setting"]])}
    columns = COLUMNS
    if cfg.instances:  # the instance's name after the seed
        table["instance"] = np.array([cfg.instances[k].name for k in cols["instance"]])
        columns = COLUMNS[:COLUMNS.index("seed") + 1] + ("instance",) + COLUMNS[COLUMNS.index("seed") + 1:]
    written.append(write_table([{c: table[c][i] for c in columns} for i in range(len(cols["setting"]))], columns,
                               folder / "runs.csv"))
    offsets = np.cumsum([0] + [len(f) for f in fronts])
    written.append(atomic_savez(folder / "fronts.npz", {"F": np.concatenate(fronts + [np.zeros((0, 2))]),
                                                         "X": np.concatenate(study.fronts_X), "offsets": offsets,
                                                         "setting": cols["setting"], "seed": cols["seed"],
                                                         **({"instance": cols["instance"]} if cfg.instances else {})}))
    rows = _order(summary.rows)
    written.append(write_table(rows, SUMMARY_COLUMNS, folder / "summary.csv"))
    verdict = _verdict(cfg, summary)
    source = str(ref.get("source", "pilot"))
    if cfg.instances:
        note = (f"Indicators on objectives normalised by each instance's own reference front, fixed before the first "
                f"run (references/, {source}; HV reference point {float(ref['hv_ref'])}); a block of the Friedman "
                "and Wilcoxon tests is one (instance, seed) pair. Intervals: percentile bootstrap of the median, "
                "resampling instances (each with its seeds), 95 %.")
    else:
        note = (f"Indicators on objectives normalised by the fixed reference front of reference.npz ({source}, "
                f"{len(ref['front'])} points; HV reference point {float(ref['hv_ref'])}). Intervals: percentile "
                "bootstrap of the median, 95 %.")
    written.append(atomic_write_text(folder / "summary.md", "\n".join(_md_table(rows)) + "\n\n" + note + "\n"))
    figures = _figures(study, folder)
    written += figures
    where = (f"{cfg.n_instances} instances (moves; the {cfg.preset} preset's limits and bounds unless an instance "
             f"gives its own)" if cfg.instances else f"the {cfg.preset} preset")
    refs = (f"each instance's own ({source}), fixed before the first run" if cfg.instances else
            f"{source}, {len(ref['front'])} points, fixed before the first run")
    md = ["# Sweep report", "",
          f"{len(cfg.settings)} settings of {', '.join(cfg.algorithms)} on {where}, "
          f"{len(cols['setting'])} runs"
          + (f" (race over at most {_blocks_word(cfg, cfg.n_blocks)}; the full grid would be {cfg.n_runs()} runs, "
             f"{100 * len(cols['setting']) / cfg.n_runs():.0f} % of it)" if cfg.race else
             f", {cfg.seeds} seeds each" + (" on every instance" if cfg.instances else ""))
          + f". Reference front: {refs}.", "",
          "## Verdict", "", *verdict, "", "## Settings", "", *_md_table(rows), "", note, ""]
    if cfg.instances:
        md += _instance_section(study, rows)
    if summary.importance:
        md += _importance_section(study)
    if summary.rounds:
        so_far = "blocks (instance, seed) so far" if cfg.instances else "seeds so far"
        md += ["## Race", "", f"| round | {so_far} | settings left |", "|---|---:|---:|"]
        done = 0
        alive_before = len(cfg.settings)
        for r, alive in enumerate(summary.rounds):
            seeds = round_seeds(cfg, r, done, alive_before)
            done = seeds.stop
            md.append(f"| {r} | {done} | {int(alive.sum())} |")
            alive_before = int(alive.sum())
        md.append("")
    md += ["## Figures", ""] + [f"![{p.stem}]({p.name})" for p in figures] + [""]
    for extend in extensions:
        section, files = extend(study, folder, log)
        md += section + [""]
        written += files
    written.append(atomic_write_text(folder / "report.md", "\n".join(md)))
    return written
