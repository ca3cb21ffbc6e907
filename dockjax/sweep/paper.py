"""The paper's comparison (§5) as a study: ``dockjax compare``.

:func:`paper_config` is a preset of the study machinery: the four algorithms of the paper
at their defaults, population 150 and 100 iterations, on common seeds (31), plus "IMOCS +
refine" (IMOCS's runs finished by gradient refinement, :func:`dockjax.optimize.refine_result`),
scored against the problem's best-known front and compared by the statistics of every
study (:mod:`.report`). All runs of an algorithm are one chunk, driven by the host driver so
that the four algorithms share the kernel's compilation.

:func:`paper_tables` is the report extension that adds what the paper shows: the
indicators it reports (ONVG, GD, SP) beside its values, the share of the best-known front's
hypervolume each algorithm reaches, Table 3 (eleven points of IMOCS's front), Table 4 (the
three trajectories of Eq. 26's types with every joint's maxima against its limits) and the
figures (fronts, the left arm's X, Y and Z, the joints of the compromise, convergence).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from .. import checks, config, metrics, plots, select
from ..algorithms import get
from ..io import atomic_write_text
from ..robot import by_kind
from .config import ConfigError, SweepConfig, size_errors
from .design import Setting
from .execute import problem_of
from .report import Study, markdown_table, write_table

__all__ = ["PAPER_ALGORITHMS", "PAPER_TYPES", "paper_config", "paper_tables", "median_run", "table3"]

PAPER_ALGORITHMS = ("nsga2", "mopso", "mocs", "imocs")
"""The algorithms of the paper's comparison, in its order."""

PAPER_TYPES = ("compromise", "time", "smooth")
"""The three trajectories of Table 4 (Eq. 26's weight types, :data:`dockjax.select.PAPER_TYPES`)."""


def paper_config(preset: str = "paper", *, seeds: int = config.N_SEEDS, pop: int = config.POP_SIZE,
                 iters: int = config.N_ITER, algorithms: Sequence[str] = PAPER_ALGORITHMS,
                 refine_steps: int = config.MEMETIC_STEPS, best_known: dict | None = None,
                 devices: int | None = None, n_control: int = config.N_FREE) -> SweepConfig:
    """The comparison of ``algorithms`` on ``preset`` as a study configuration: every
    algorithm at its default hyper-parameters, ``seeds`` runs each in one chunk, and with
    ``refine_steps`` > 0 an "IMOCS + refine" setting (IMOCS's runs, each final population
    polished by that many steps of gradient refinement). The reference is the best-known
    front (``best_known`` overrides :data:`dockjax.config.BEST_KNOWN`); ``n_control`` the
    problem's free control points. Raises ConfigError naming the option."""
    errors = [f"--{name} must be >= {lo}, got {v}" for name, v, lo in (
        ("seeds", seeds, 1), ("pop", pop, 4), ("iters", iters, 1), ("refine-steps", refine_steps, 0)) if v < lo]
    errors += [f"--{name} {v} is too large (at most {hi})" for name, v, hi in (
        ("seeds", seeds, config.MAX_COUNT), ("pop", pop, config.MAX_COUNT), ("iters", iters, config.MAX_COUNT),
        ("refine-steps", refine_steps, config.MAX_COUNT)) if v > hi]
    if not errors:
        errors += size_errors(list(algorithms) + ["imocs"] * bool(refine_steps), [], (pop,), (iters,), None, 0, seeds,
                               seeds)
    if not (checks.is_integer(n_control) and 1 <= n_control <= config.MAX_CONTROL):
        errors.append(f"--n-control must be an integer from 1 to {config.MAX_CONTROL}, got {n_control!r}")
    if preset not in config.PRESETS:
        errors.append(f"--presets: {preset!r} is not one of {', '.join(config.PRESETS)}")
    try:
        names = [get(a).name for a in algorithms]
    except ValueError as exc:
        errors.append(f"--algorithms: {exc}")
        names = []
    if not algorithms:
        errors.append("--algorithms must name at least one algorithm")
    if len(set(names)) != len(names):
        errors.append(f"--algorithms names an algorithm twice: {names}")
    best = {**config.BEST_KNOWN, **(best_known or {})}
    ranges = (("n_points", "--best-known-points", 2, 10_000), ("n_exact", "--best-known-anchors", 2, 1_000),
              ("steps", "--best-known-steps", 1, 100_000))
    for key, option, lo, hi in ranges:
        if not lo <= best[key] <= hi:
            errors.append(f"{option} must be from {lo} to {hi}, got {best[key]}")
    if errors:
        raise ConfigError("; ".join(errors))
    settings = [Setting(a, pop, iters) for a in names]
    if refine_steps and "imocs" in names:
        settings.append(Setting("imocs", pop, iters, (), refine_steps))
    return SweepConfig(settings=tuple(settings), preset=preset, seeds=seeds, chunk=seeds,
                       reference={"kind": "best-known", **best}, devices=devices, driver="host",
                       n_control=int(n_control) if checks.is_integer(n_control) else config.N_FREE)


def median_run(study: Study, setting: int) -> int:
    """The run (an index of ``study.cols``) of median hypervolume among one setting's
    runs (the upper median for an even count)."""
    runs = study.runs_of(setting)
    hv = study.cols["HV"][runs]
    return int(runs[np.argsort(hv, kind="stable")[len(hv) // 2]])


def table3(front: np.ndarray, k: int = 11) -> np.ndarray:
    """k points spread uniformly in T along a front sorted by T (the paper's Table 3). → (k', 2)."""
    targets = np.linspace(front[0, 0], front[-1, 0], k)
    idx = np.unique([int(np.argmin(np.abs(front[:, 0] - t))) for t in targets])
    return front[idx]


def _chosen(study: Study, run: int) -> dict[str, dict]:
    """The three trajectories of Table 4 from one run's front, with every joint's maximum
    |travel|, |velocity| and |acceleration| (the kernel's columns with every span through
    the root chain: exact, never understated)."""
    problem = problem_of(study.cfg.preset, study.cfg.n_control)
    F, X = study.fronts[run], study.fronts_X[run]
    out = {}
    for kind in PAPER_TYPES:
        j = select.choose_type(F, kind)
        G = problem.evaluate(X[j][None], screen=False)[1][0]
        out[kind] = {"x": X[j], "T": float(F[j, 0]), "jerk": float(F[j, 1]),
                     "maxima": (by_kind(G) + 1.0) * np.asarray(problem.limits)}
    return out


def _fmt(v: float) -> str:
    return f"{v:.4g}"


def paper_tables(study: Study, out: Path, log: Callable[[str], None] = print) -> tuple[list[str], list[Path]]:
    """The report extension of ``dockjax compare`` (see the module docstring): writes
    ``paper.csv``, ``table3.csv``, ``table4.csv``, ``chosen.json``, ``fronts.png``,
    ``left_arm_xyz.png``, ``joints.png`` and ``convergence.png`` into ``out``; returns the
    lines of ``report.md``'s section and the files."""
    cfg, cols = study.cfg, study.cols
    problem = problem_of(cfg.preset, cfg.n_control)
    ref = study.ref["front"]
    hv_front = metrics.indicators(ref, None, ref, hv_ref=float(study.ref["hv_ref"]))["HV"]
    files: list[Path] = []
    # the indicators the paper reports, beside its values
    rows = []
    for i, s in enumerate(cfg.settings):
        runs = study.runs_of(i)
        if not runs.size:
            continue
        med = {k: float(np.nanmedian(cols[k][runs])) for k in ("ONVG", "GD", "SP", "IGD+", "HV")}
        paper = config.PAPER_INDICATORS.get(s.name, (np.nan,) * 3)
        rows.append({"algorithm": s.name, "runs": int(runs.size), "ONVG": med["ONVG"], "GD": med["GD"],
                     "SP": med["SP"], "IGD+": med["IGD+"], "HV": med["HV"],
                     "HV_percent_of_reference": 100 * med["HV"] / hv_front,
                     "paper_ONVG": paper[0], "paper_GD": paper[1], "paper_SP": paper[2]})
        log(f"[{cfg.preset}] {s.name:>12}: HV {med['HV']:.4f} ({100 * med['HV'] / hv_front:.2f} % of the reference "
            f"front's), IGD+ {med['IGD+']:.4f}, GD {med['GD']:.5f}, SP {med['SP']:.5f}, ONVG {med['ONVG']:.0f} "
            "(medians)")
    columns = list(rows[0])
    files.append(write_table(rows, columns, out / "paper.csv"))
    md = ["## The paper's comparison", "",
          f"Medians over the seeds; the paper reports one run per algorithm. HV % is the share of the reference "
          f"front's hypervolume ({hv_front:.4f} under the same normalisation).", "",
          *markdown_table(["algorithm", "runs", "ONVG (paper)", "GD (paper)", "SP (paper)", "IGD+", "HV",
                           "HV % of reference"],
                          [[r["algorithm"], str(r["runs"]), f"{r['ONVG']:.0f} ({_fmt(r['paper_ONVG'])})",
                            f"{_fmt(r['GD'])} ({_fmt(r['paper_GD'])})", f"{_fmt(r['SP'])} ({_fmt(r['paper_SP'])})",
                            _fmt(r["IGD+"]), _fmt(r["HV"]), f"{r['HV_percent_of_reference']:.1f}"] for r in rows]), ""]
    # Tables 3 and 4 from IMOCS's run of median hypervolume (the first algorithm's without IMOCS)
    plain = [i for i, s in enumerate(cfg.settings) if not s.refine_steps]
    base = next((i for i in plain if cfg.settings[i].algorithm == "imocs"), plain[0])
    run = median_run(study, base)
    front = study.fronts[run]
    name = cfg.settings[base].name
    figures: list[Path] = []
    if len(front):
        t3 = [{"serial": k + 1, "T_s": f[0], "jerk": f[1]} for k, f in enumerate(table3(front))]
        files.append(write_table(t3, ("serial", "T_s", "jerk"), out / "table3.csv"))
        chosen = _chosen(study, run)
        t4 = []
        for kind, c in chosen.items():
            row = {"type": kind, "T_s": c["T"], "jerk": c["jerk"]}
            for j, jn in enumerate(config.JOINT_NAMES):
                row[f"{jn}_max_vel"] = c["maxima"][j, 1]
                row[f"{jn}_vel_limit"] = float(problem.limits[j, 1])
                row[f"{jn}_max_acc"] = c["maxima"][j, 2]
                row[f"{jn}_acc_limit"] = float(problem.limits[j, 2])
            t4.append(row)
        files.append(write_table(t4, list(t4[0]), out / "table4.csv"))
        doc = {k: {"x": c["x"].tolist(), "T": c["T"], "jerk": c["jerk"]} for k, c in chosen.items()}
        files.append(atomic_write_text(out / "chosen.json", json.dumps(doc, indent=2) + "\n"))
        md += [f"### Table 3: eleven points of the front of {name}'s run of median HV (seed "
               f"{int(cols['seed'][run])})", "",
               *markdown_table(["serial", "T [s]", "jerk"], [[str(r["serial"]), _fmt(r["T_s"]), _fmt(r["jerk"])]
                                                             for r in t3]), "",
               "### Table 4: the trajectories of Eq. 26's three types, and the largest |velocity| and "
               "|acceleration| of each joint against its limit", "",
               *markdown_table(["type", "T [s]", "jerk"] + [f"{jn} vel / acc" for jn in config.JOINT_NAMES],
                               [[r["type"], _fmt(r["T_s"]), _fmt(r["jerk"])]
                                + [f"{_fmt(r[f'{jn}_max_vel'])}/{_fmt(r[f'{jn}_vel_limit'])}, "
                                   f"{_fmt(r[f'{jn}_max_acc'])}/{_fmt(r[f'{jn}_acc_limit'])}"
                                   for jn in config.JOINT_NAMES] for r in t4]), ""]
        samples = {}
        for kind, c in chosen.items():
            traj = problem.decode(c["x"])
            t = np.linspace(0.0, traj.T, 600)
            samples[f"{kind} (T={c['T']:.1f} s)"] = {"t": t, "pose": traj.pose(t), "pose_vel": traj.pose(t, 1),
                                                     "pose_acc": traj.pose(t, 2)}
        figures.append(plots.plot_left_arm(samples, out / "left_arm_xyz.png"))
        traj = problem.decode(chosen["compromise"]["x"])
        t = np.linspace(0.0, traj.T, 600)
        figures.append(plots.plot_joints({"t": t, "position": traj.joints(t), "velocity": traj.joints(t, 1),
                                          "acceleration": traj.joints(t, 2)}, problem.limits, out / "joints.png",
                                         title="joints of the compromise trajectory", home=problem.home))
    fronts = {cfg.settings[i].name: study.fronts[median_run(study, i)] for i in range(len(cfg.settings))
              if study.runs_of(i).size}
    figures.insert(0, plots.plot_fronts(fronts, out / "fronts.png", reference=ref,
                                        reference_label=f"reference ({str(study.ref['source'])})",
                                        title=f"fronts of the median-HV runs ({cfg.preset})"))
    # a memetic setting's history is its optimiser's (before refinement): not drawn twice
    hist = {cfg.settings[i].name: np.stack([study.history[k] for k in study.runs_of(i)]) for i in plain
            if study.runs_of(i).size}
    figures.append(plots.plot_convergence(hist, out / "convergence.png",
                                          title="hypervolume of the feasible set (normalised), median and IQR"))
    md += [f"![{p.stem}]({p.name})" for p in figures]
    return md, files + figures
