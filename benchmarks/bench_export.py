"""Controller exports: how closely a ROS 2 controller's quintic interpolation of the exported points follows the plan.

    python benchmarks/bench_export.py [--rates 1000 250 100 25 5 1] [--presets paper wide] [--figure export.png]
    python benchmarks/bench_export.py --rates 50 5 --presets paper --n-front 2 --figure dev.png  # quick

For each preset, the plan ``dockjax plan`` makes by default (the paper preset: the
compromise of Eq. 26; the wide preset: its shortest time, where limits bind) is exported
(:func:`dockjax.export.joint_trajectory`) at each rate. The points are interpolated as a
joint trajectory controller does (per joint and segment, the quintic matching position,
velocity and acceleration at both ends: SciPy's ``BPoly.from_derivatives``) and compared
with the plan at 20 times per point: the largest deviation of the linear joints (µm) and
of the rotary ones (µrad), and the interpolant's largest velocity and acceleration as a
fraction of their limits. Also the number of points, the median time of building the
message and writing its YAML and JSON (of ``--repeats``), and the files' size. With
``--figure``, the largest deviations against the rate.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.interpolate import BPoly

from dockjax import config, export
from dockjax.plan import plan
from dockjax.plots import plot_deviation
from dockjax.problem import make_problem

SELECT = {"paper": (1.0, 1.0), "wide": (1.0, 0.0)}
"""The weights of each preset's plan: the compromise on the paper's move, the shortest time on the wide one."""


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", type=float, nargs="+", default=[1000.0, 250.0, 100.0, 25.0, 5.0, 1.0],
                    help="export rates [Hz]")
    ap.add_argument("--presets", nargs="+", choices=tuple(SELECT), default=list(SELECT))
    ap.add_argument("--n-front", type=int, default=config.PLAN_FRONT, help="time caps of each plan's front")
    ap.add_argument("--repeats", type=int, default=3, help="timed repeats of the export")
    ap.add_argument("--figure", default=None, help="write each joint's deviation over time (first rate) here")
    a = ap.parse_args(argv)
    if a.repeats < 1:
        ap.error(f"--repeats must be >= 1, got {a.repeats}")
    scale = np.array([export.SI_SCALE[u] for u in config.JOINT_UNITS])
    linear = np.array([u == "mm" for u in config.JOINT_UNITS])
    print("| preset | plan T [s] | rate [Hz] | points | max deviation, linear [µm] | max deviation, rotary [µrad] "
          "| peak velocity / limit | peak acceleration / limit | export [s] | YAML + JSON [MB] |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    curves = {}
    for preset in a.presets:
        problem = make_problem(preset)
        p = plan(problem, weights=SELECT[preset], n_front=a.n_front)
        tr = p.trajectory
        for rate in a.rates:
            times = []
            for _ in range(a.repeats):
                t0 = time.perf_counter()
                msg = export.joint_trajectory(tr, rate)
                size = len(export.to_yaml(msg)) + len(export.to_json(msg))
                times.append(time.perf_counter() - t0)
            pts = msg["points"]
            t = np.array([q["time_from_start"]["sec"] + q["time_from_start"]["nanosec"] / export.NS for q in pts])
            P, V, A = (np.array([q[k] for q in pts]) / scale for k in ("positions", "velocities", "accelerations"))
            dense = np.linspace(0.0, t[-1], 20 * len(t) + 1)
            truth = tr.at(np.minimum(dense, tr.T))["position"]
            quintic = [BPoly.from_derivatives(t, np.stack([P[:, j], V[:, j], A[:, j]], 1)) for j in range(8)]
            dev = np.stack([np.abs(q(dense) - truth[:, j]) for j, q in enumerate(quintic)], 1)
            peaks = [max(np.abs(q(dense, k)).max() / problem.limits[j, k] for j, q in enumerate(quintic))
                     for k in (1, 2)]
            lin, rot = dev[:, linear].max() * 1e3, dev[:, ~linear].max() * config.DEG * 1e6
            print(f"| {preset} | {tr.T:.3f} | {rate:g} | {len(t)} | {lin:.2e} | {rot:.2e} | {peaks[0]:.6f} | "
                  f"{peaks[1]:.6f} | {np.median(times):.2f} | {size / 1e6:.1f} |", flush=True)
            curves.setdefault(f"{preset}, linear joints [µm]", []).append((rate, lin))
            curves.setdefault(f"{preset}, rotary joints [µrad]", []).append((rate, rot))
    if a.figure:
        lines = {label: tuple(np.array(v) for v in zip(*points)) for label, points in curves.items()}
        path = plot_deviation(lines, a.figure, xlabel="export rate [Hz]", ylabel="largest |controller − plan|",
                              title="quintic interpolation of the exported points")
        print(f"wrote {path}")

if __name__ == "__main__":
    main()
