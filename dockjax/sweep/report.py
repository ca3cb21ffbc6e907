"""The report of a finished sweep folder: runs.csv, fronts.npz, summary.csv/.md (per
setting, best median HV first), the printed table and the figures."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from .. import plots
from ..io import atomic_savez, atomic_write_text
from .config import COLUMNS
from .files import load_npz

__all__ = ["load_table", "report"]


def _fmt(v) -> str:
    if isinstance(v, (str, np.str_)):
        return str(v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return repr(float(v))


def load_table(out: Path) -> tuple[dict[str, np.ndarray], list[np.ndarray]]:
    """Every chunk file of ``out`` merged: columns sorted by run id, and each run's front."""
    parts = [load_npz(p) for p in sorted((Path(out) / "chunks").glob("chunk-*.npz"))]
    if not parts:
        raise RuntimeError(f"no chunk files in {out / 'chunks'}")
    cols = {k: np.concatenate([p[k] for p in parts]) for k in ("run_id",) + COLUMNS}
    fronts = [p["front_F"][o0:o1] for p in parts for o0, o1 in zip(p["front_offsets"][:-1], p["front_offsets"][1:])]
    order = np.argsort(cols["run_id"], kind="stable")
    return {k: v[order] for k, v in cols.items()}, [fronts[i] for i in order]


def _settings_summary(cols: dict[str, np.ndarray]) -> list[dict]:
    keys = list(zip(cols["pop"].tolist(), cols["rho"].tolist(), cols["alpha_max"].tolist()))
    rows = []
    seen: dict = {}
    for i, k in enumerate(keys):
        seen.setdefault(tuple("nan" if isinstance(x, float) and math.isnan(x) else x for x in k), []).append(i)
    for k, idx in seen.items():
        idx = np.asarray(idx)
        hv = cols["HV"][idx]
        q1, med, q3 = np.nanpercentile(hv, [25, 50, 75]) if np.isfinite(hv).any() else (np.nan,) * 3
        row = {"pop": int(k[0]), "rho": cols["rho"][idx[0]], "alpha_max": cols["alpha_max"][idx[0]],
               "runs": len(idx), "HV_median": med, "HV_iqr": q3 - q1, "_q": (q1, q3)}
        for ind in ("IGD", "IGD+", "GD", "SP", "ONVG"):
            v = cols[ind][idx].astype(float)
            row[f"{ind}_median"] = float(np.nanmedian(v)) if np.isfinite(v).any() else np.nan
        row["_idx"] = idx
        rows.append(row)
    rows.sort(key=lambda r: (-(r["HV_median"] if np.isfinite(r["HV_median"]) else -np.inf),
                             r["pop"], np.nan_to_num(r["rho"]), np.nan_to_num(r["alpha_max"])))
    return rows


def _label(row) -> str:
    if math.isnan(row["rho"]):
        return f"pop {row['pop']}"
    return f"pop {row['pop']}, ρ={row['rho']:g}, α_max={row['alpha_max']:g}"


def report(out: Path, *, top: int = 10, log: Callable[[str], None] = print) -> list[Path]:
    """Tables and figures of a finished sweep folder (every file atomically)."""
    out = Path(out)
    cols, fronts = load_table(out)
    ref = load_npz(out / "reference.npz")
    written = []
    lines = [",".join(COLUMNS)] + [",".join(_fmt(cols[c][i]) for c in COLUMNS) for i in range(len(cols["run_id"]))]
    atomic_write_text(out / "runs.csv", "\n".join(lines) + "\n")
    written.append(out / "runs.csv")
    offsets = np.cumsum([0] + [len(f) for f in fronts])
    atomic_savez(out / "fronts.npz", {"F": np.concatenate(fronts + [np.zeros((0, 2))]), "offsets": offsets,
                                       **{k: cols[k] for k in ("run_id", "pop", "rho", "alpha_max", "seed")}})
    written.append(out / "fronts.npz")

    rows = _settings_summary(cols)
    scols = [k for k in rows[0] if not k.startswith("_")]
    csv = [",".join(scols)] + [",".join(_fmt(r[c]) for c in scols) for r in rows]
    atomic_write_text(out / "summary.csv", "\n".join(csv) + "\n")
    md = ["| " + " | ".join(scols) + " |", "|" + "---|" * len(scols)]
    md += ["| " + " | ".join(f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c]) for c in scols) + " |"
           for r in rows]
    note = (f"\nIndicators on objectives normalised by the fixed reference front of reference.npz "
            f"({str(ref.get('source', 'pilot'))}, {len(ref['front'])} points; "
            f"HV reference point {float(ref['hv_ref'])}).\n")
    atomic_write_text(out / "summary.md", "\n".join(md) + "\n" + note)
    written += [out / "summary.csv", out / "summary.md"]

    algo = str(cols["algorithm"][0])
    log(f"\n{algo}: {len(cols['run_id'])} runs, {len(rows)} settings; best by median HV "
        f"(reference fixed at sweep start: {str(ref.get('source', 'pilot'))}, {len(ref['front'])} points)")
    log(f"{'rank':>4}  {'setting':<34} {'HV median':>10} {'IQR':>8} {'IGD':>8} {'GD':>9} {'SP':>8} {'ONVG':>5}")
    for k, r in enumerate(rows[:top]):
        log(f"{k + 1:>4}  {_label(r):<34} {r['HV_median']:>10.4f} {r['HV_iqr']:>8.4f} {r['IGD_median']:>8.4f} "
            f"{r['GD_median']:>9.5f} {r['SP_median']:>8.5f} {r['ONVG_median']:>5.0f}")
    if len(rows) > top:
        log(f"      ... {len(rows) - top} more in {out / 'summary.csv'}")

    # heat maps of median HV over rho x alpha_max, per population size (IMOCS)
    if not np.isnan(cols["rho"]).all():
        for pop in sorted({r["pop"] for r in rows}):
            sub = [r for r in rows if r["pop"] == pop]
            rhos = sorted({r["rho"] for r in sub})
            alphas = sorted({r["alpha_max"] for r in sub})
            M = np.full((len(rhos), len(alphas)), np.nan)
            for r in sub:
                M[rhos.index(r["rho"]), alphas.index(r["alpha_max"])] = r["HV_median"]
            written.append(plots.plot_heatmap(M, rhos, alphas, out / f"heatmap_hv_pop{pop}.png",
                                              xlabel="α_max", ylabel="ρ", title=f"{algo}: median HV, pop {pop}"))
    # HV against population size, one line per (rho, alpha_max)
    groups: dict = {}
    for r in rows:
        groups.setdefault((_fmt(r["rho"]), _fmt(r["alpha_max"])), []).append(r)
    lines = {}
    for (rho, alpha), rs in sorted(groups.items()):
        rs = sorted(rs, key=lambda r: r["pop"])
        label = algo if rho == "nan" else f"ρ={float(rho):g}, α_max={float(alpha):g}"
        lines[label] = (np.array([r["pop"] for r in rs], float), np.array([r["HV_median"] for r in rs]),
                        np.array([r["_q"] for r in rs]).reshape(-1, 2))
    written.append(plots.plot_median_iqr(lines, out / "hv_vs_pop.png", xlabel="population size",
                                         ylabel="hypervolume (median, bar = IQR)",
                                         title=f"{algo}: HV against population size"))
    # fronts of the best and the worst setting
    groups = {f"{what}: {_label(r)} (HV {r['HV_median']:.3f})": [fronts[i] for i in r["_idx"]]
              for r, what in ((rows[0], "best"), (rows[-1], "worst"))[: 1 if len(rows) == 1 else 2]}
    written.append(plots.plot_front_groups(groups, ref["front"], out / "fronts_best_worst.png",
                                           reference_label="reference front (fixed at sweep start)",
                                           title=f"{algo}: fronts of every seed, best and worst setting by median HV"))
    log(f"wrote {', '.join(p.name for p in written)} to {out}")
    return written
