"""The paper's comparison (§5) with statistics: runs, reference front, indicators, tables,
the choice of three trajectories, and the files of ``experiments/compare.py``.

Data flow: :func:`run_study` runs every algorithm for every seed (all seeds of an
algorithm batched; ``driver="host"``, so the algorithms share the kernel's compilation)
→ the reference front is the non-dominated union of every final feasible set
(conventions §8) → indicators per run on objectives normalised by that front → per-algorithm
medians, interquartile ranges, best runs and a rank-sum test against IMOCS → Table 3 and
Table 4 analogues from the IMOCS run of median hypervolume.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import mannwhitneyu

from . import config, metrics, plots, select
from .io import atomic_savez, atomic_write_text
from .optimize import Result, optimize, refine_result
from .problem import DockingProblem, bucket_rows, make_problem
from .refine import FrontResult

__all__ = ["study_right_arm", "refine_rows", "hv_reference", "run_study", "Study",
           "summary_table", "write_study"]

INDICATORS = ("ONVG", "GD", "SP", "IGD", "HV", "HV_fraction")
TYPES = ("compromise", "time", "smooth")


STUDY_RIGHT_ARM = "adaptive"
"""Right-arm treatment of the comparison's problems (see :class:`DockingProblem`) when it
runs several presets. ``"adaptive"`` scores exactly as ``"bound"`` wherever the bound is
within conventions §6's tolerance — every candidate of the ``paper`` preset, where ``"auto"``
picks ``"bound"`` — and by the ``"taylor"`` treatment elsewhere; with one setting for every preset, the
presets share every compiled program (same shapes, same static settings), which saves
compare.py a whole set of compilations (~1 minute here). A single preset keeps its
``"auto"`` choice (nothing to share; ``"bound"`` compiles faster)."""

REFINE_ROWS = 256
"""Most rows per compiled call of the refinements of a study (see :func:`refine_rows`)."""


def study_right_arm(presets) -> str:
    """:data:`STUDY_RIGHT_ARM` for several presets, ``"auto"`` for one."""
    return STUDY_RIGHT_ARM if len(set(presets)) > 1 else "auto"


def refine_rows(*sizes: int) -> int:
    """Rows per compiled call shared by every refinement of a study (the best-known front,
    the memetic rows), given their row counts: the kernel's bucket of the largest, at most
    :data:`REFINE_ROWS`; so one compiled program serves them all."""
    return min(REFINE_ROWS, bucket_rows(max(sizes)))


def hv_reference(problem: DockingProblem) -> np.ndarray:
    """A fixed reference point (objective units) for convergence curves, set before any run:
    T = 6 h_max, and twice the jerk of the straight-line trajectory at the shortest
    intervals (a fast, plain candidate)."""
    lo, hi = problem.interval_bounds
    x = np.concatenate([np.full(6, lo), np.linspace(problem.start, problem.goal, 7)[1:6].ravel()])
    F, _ = problem.evaluate(x[None, : problem.n_var])
    return np.array([6 * hi, 2 * F[0, 1]])


@dataclass
class Study:
    preset: str
    problem: DockingProblem
    results: dict[str, Result]
    reference_front: np.ndarray
    ideal: np.ndarray
    nadir: np.ndarray
    per_run: dict[str, dict[str, np.ndarray]]
    seconds: float
    reference_kind: str = "union"
    """``"best-known"`` (the independent front of :func:`dockjax.refine.best_known_front`) or
    ``"union"`` (non-dominated union of every final feasible set, conventions §8)."""
    best_known: FrontResult | None = None

    @property
    def reference_description(self) -> str:
        if self.reference_kind == "best-known":
            return (f"best-known front ({len(self.reference_front)} points: ε-constraint sweep of T with "
                    f"gradient refinement, computed without the algorithms' fronts)")
        return (f"non-dominated union of every final feasible set ({len(self.reference_front)} points)")


def run_study(preset: str, *, algorithms=("nsga2", "mopso", "mocs", "imocs"), seeds=range(31),
              pop_size: int = config.POP_SIZE, n_iter: int = config.N_ITER, refine_steps: int = 0,
              best_known: FrontResult | None = None, right_arm: str = "auto", refine_rows: int | None = None,
              log=print) -> Study:
    """Run every algorithm for every seed and score them (conventions §8).

    ``refine_steps > 0`` adds ``"imocs+refine"``: the IMOCS runs finished by gradient
    refinement (:func:`dockjax.algorithms.refine_result`). ``best_known`` (from
    :func:`dockjax.refine.best_known_cached`) becomes the reference front of the indicators; without it the
    reference is the non-dominated union of every final feasible set. ``right_arm``: the
    problem's right-arm treatment (:func:`study_right_arm`); ``refine_rows``: rows per
    compiled call of the refinement (:func:`refine_rows`; default its own bucket).
    """
    t0 = time.perf_counter()
    problem = make_problem(preset, right_arm)
    ref_point = hv_reference(problem)
    results = {}
    for name in algorithms:
        # the host driver: the four algorithms (and both presets) share the kernel's
        # compiled program, which saves more compile time than it costs in run time here
        r = optimize(name, problem, seeds=list(seeds), pop_size=pop_size, n_iter=n_iter, hv_ref=ref_point,
                     driver="host")
        log(f"[{preset}] {name}: {len(r)} runs in {r.seconds:.1f} s (compile included)")
        results[name] = r
    if refine_steps and "imocs" in results:
        r = refine_result(problem, results["imocs"], steps=refine_steps, rows=refine_rows)
        log(f"[{preset}] imocs+refine: {r.extra['improved'].sum()} of {r.extra['improved'].size} members "
            f"improved in {r.extra['refine_seconds']:.1f} s ({refine_steps} steps, compile included)")
        results["imocs+refine"] = r
    if best_known is not None and len(best_known.F):
        ref_front, kind = metrics.nondominated_points(best_known.F), "best-known"
    else:
        union = np.concatenate([f for r in results.values() for f in r.fronts() if len(f)] or [np.zeros((0, 2))])
        ref_front, kind = metrics.nondominated_points(union), "union"
    ideal, nadir = ref_front.min(0), ref_front.max(0)
    hv_ref_front = metrics.indicators(ref_front, None, ref_front)["HV"]
    per_run = {}
    for name, r in results.items():
        rows = [metrics.indicators(r.F[i], r.front[i], ref_front) for i in range(len(r))]
        per_run[name] = {k: np.array([row[k] for row in rows]) for k in rows[0]}
        per_run[name]["HV_fraction"] = per_run[name]["HV"] / hv_ref_front
        # points of a run's front below the reference front (its piecewise-linear
        # interpolation in T) by more than 0.1 % in jerk
        per_run[name]["beyond_ref"] = np.array([int(np.sum(_below(f, ref_front))) for f in r.fronts()])
    return Study(preset, problem, results, ref_front, ideal, nadir, per_run, time.perf_counter() - t0,
                 reference_kind=kind, best_known=best_known)


def _below(F: np.ndarray, R: np.ndarray, rtol: float = 1e-3) -> np.ndarray:
    """(k,) True where a row (T, jerk) of F lies below the front R — jerk more than ``rtol``
    under R's piecewise-linear interpolation at that T — or left of it (T < min T of R)."""
    if len(F) == 0:
        return np.zeros(0, bool)
    R = R[np.argsort(R[:, 0])]
    inside = F[:, 0] >= R[0, 0]
    return ~inside | (F[:, 1] < (1.0 - rtol) * np.interp(F[:, 0], R[:, 0], R[:, 1]))


def summary_table(study: Study) -> list[dict]:
    """Per algorithm and indicator: median, IQR, best run, rank-sum p-value against IMOCS."""
    rows = []
    base = study.per_run.get("imocs")
    for name, vals in study.per_run.items():
        row = {"algorithm": name, "runs": len(study.results[name])}
        for ind in INDICATORS:
            v = vals[ind]
            q1, med, q3 = np.nanpercentile(v, [25, 50, 75])
            best = np.nanmin(v) if ind in ("GD", "IGD", "SP") else np.nanmax(v)
            row[f"{ind}_median"], row[f"{ind}_iqr"], row[f"{ind}_best"] = med, q3 - q1, best
            if base is not None and name != "imocs":
                a, b = v[np.isfinite(v)], base[ind][np.isfinite(base[ind])]
                p = mannwhitneyu(a, b).pvalue if len(a) and len(b) and np.ptp(np.r_[a, b]) > 0 else 1.0
                row[f"{ind}_p_vs_imocs"] = p
            else:
                row[f"{ind}_p_vs_imocs"] = np.nan
        row["points_beyond_reference"] = int(np.sum(vals["beyond_ref"]))
        rows.append(row)
    return rows


def median_run(study: Study, name: str) -> int:
    """Index of the run of median hypervolume."""
    hv = study.per_run[name]["HV"]
    return int(np.argsort(hv)[len(hv) // 2])


def table3(front: np.ndarray, k: int = 11) -> np.ndarray:
    """k points spread uniformly in T along a front (the paper's Table 3). → (k', 2)."""
    targets = np.linspace(front[0, 0], front[-1, 0], k)
    idx = np.unique([int(np.argmin(np.abs(front[:, 0] - t))) for t in targets])
    return front[idx]


def chosen_trajectories(study: Study, name: str = "imocs") -> dict[str, dict]:
    """The three trajectories of Table 4 from the median run's front, with the maximum
    |velocity| and |acceleration| of every joint beside its limit (exact: full root chain)."""
    r = study.results[name]
    i = median_run(study, name)
    m = r.front[i]
    F, X, G = r.F[i][m], r.X[i][m], r.G[i][m]
    order = np.argsort(F[:, 0])
    F, X, G = F[order], X[order], G[order]
    out = {}
    for kind in TYPES:
        j = select.choose_type(F, kind)
        # exact maxima (every span through the root chain): the run's screened G may
        # overstate columns far from their limits by up to 0.9 % of the limit
        G_exact = study.problem.evaluate(X[j][None], screen=False)[1][0]
        maxima = (G_exact.reshape(8, 3) + 1.0) * study.problem.limits
        out[kind] = {"x": X[j], "T": F[j, 0], "jerk": F[j, 1], "G": G[j], "maxima": maxima}
    return out


def _fmt(v) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return f"{v:.4g}"


def _write_table(rows: list[dict], stem: Path, note: str = "") -> None:
    cols = list(rows[0])
    csv = [",".join(cols)] + [",".join(_fmt(r[c]) for c in cols) for r in rows]
    atomic_write_text(stem.with_suffix(".csv"), "\n".join(csv) + "\n")
    md = ([note, ""] if note else []) + ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    md += ["| " + " | ".join(_fmt(r[c]) for c in cols) + " |" for r in rows]
    atomic_write_text(stem.with_suffix(".md"), "\n".join(md) + "\n")


def write_study(study: Study, out: Path) -> list[Path]:
    """Write every table, figure and the raw data of one preset into ``out/<preset>/``."""
    folder = Path(out) / study.preset
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    rows = summary_table(study)
    _write_table(rows, folder / "indicators", note=(
        f"Indicators on objectives normalised by the reference front: {study.reference_description}. "
        "HV_fraction = HV / HV of the reference front (same normalisation and reference point 1.1); "
        "points_beyond_reference counts front points, over all runs, more than 0.1 % below the reference "
        "front (its piecewise-linear interpolation in T) or faster than its fastest point."))
    atomic_write_text(folder / "reference.txt", study.reference_description + "\n")
    written.append(folder / "reference.txt")
    written += [folder / "indicators.csv", folder / "indicators.md"]
    # per-run indicators (every number of the table can be recomputed from these)
    per = [{"algorithm": n, "seed": int(s), **{k: v[i] for k, v in vals.items()}}
           for n, vals in study.per_run.items() for i, s in enumerate(study.results[n].seeds)]
    _write_table(per, folder / "runs")
    written += [folder / "runs.csv"]
    # raw data
    raw = {}
    for n, r in study.results.items():
        raw.update({f"{n}_X": r.X, f"{n}_F": r.F, f"{n}_G": r.G, f"{n}_front": r.front,
                    f"{n}_seeds": r.seeds, f"{n}_history": r.history})
    raw["reference_front"] = study.reference_front
    raw["reference_kind"] = np.array(study.reference_kind)
    if study.best_known is not None:
        raw.update({"best_known_X": study.best_known.X, "best_known_F": study.best_known.F})
    atomic_savez(folder / "raw.npz", raw, compressed=True)
    written.append(folder / "raw.npz")
    # Table 3 and Table 4 analogues
    i = median_run(study, "imocs") if "imocs" in study.results else 0
    name = "imocs" if "imocs" in study.results else next(iter(study.results))
    front = study.results[name].fronts()[i]
    t3 = ([{"serial": k + 1, "T_s": f[0], "jerk": f[1]} for k, f in enumerate(table3(front))] if len(front)
          else [{"serial": 0, "T_s": np.nan, "jerk": np.nan}])
    _write_table(t3, folder / "table3")
    written += [folder / "table3.csv", folder / "table3.md"]
    chosen = chosen_trajectories(study, name) if len(front) else {}
    t4 = []
    for kind, c in chosen.items():
        row = {"type": kind, "T_s": c["T"], "jerk": c["jerk"]}
        for j, jn in enumerate(config.JOINT_NAMES):
            row[f"{jn}_max_vel"] = c["maxima"][j, 1]
            row[f"{jn}_vel_limit"] = study.problem.limits[j, 1]
            row[f"{jn}_max_acc"] = c["maxima"][j, 2]
            row[f"{jn}_acc_limit"] = study.problem.limits[j, 2]
        t4.append(row)
    if t4:
        _write_table(t4, folder / "table4")
        written += [folder / "table4.csv", folder / "table4.md"]
        doc = {k: {"x": c["x"].tolist(), "T": float(c["T"]), "jerk": float(c["jerk"])} for k, c in chosen.items()}
        atomic_write_text(folder / "chosen.json", json.dumps(doc, indent=2))
        written.append(folder / "chosen.json")
    # figures
    fronts = {n: r.fronts()[median_run(study, n)] for n, r in study.results.items()}
    written.append(plots.plot_fronts(fronts, folder / "fronts.png", reference=study.reference_front,
                                     reference_label=f"reference ({study.reference_kind})",
                                     title=f"fronts of the median-HV runs ({study.preset})"))
    if chosen:
        samples = {}
        for kind, c in chosen.items():
            traj = study.problem.decode(c["x"])
            t = np.linspace(0.0, traj.T, 600)
            samples[f"{kind} (T={c['T']:.1f} s)"] = {
                "t": t, "pose": traj.pose(t), "pose_vel": traj.pose(t, 1), "pose_acc": traj.pose(t, 2)}
        written.append(plots.plot_left_arm(samples, folder / "left_arm_xyz.png"))
        traj = study.problem.decode(chosen["compromise"]["x"])
        t = np.linspace(0.0, traj.T, 600)
        sample = {"t": t, "position": traj.joints(t), "velocity": traj.joints(t, 1),
                  "acceleration": traj.joints(t, 2)}
        written.append(plots.plot_joints(sample, study.problem.limits, folder / "joints.png",
                                         title="joints of the compromise trajectory"))
    # a memetic run's history is its optimiser's (before refinement): not drawn twice
    hist = {n: r.history for n, r in study.results.items() if r.history is not None and "+refine" not in n}
    ref = np.round(hv_reference(study.problem), 3).tolist()
    written.append(plots.plot_convergence(hist, folder / "convergence.png", title=f"hypervolume (ref {ref})"))
    return written


