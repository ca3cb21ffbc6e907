"""End to end: experiments/compare.py and the installed `dockjax plan` script."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dockjax import DockingProblem
from tests import reference as R

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(sys.executable).parent / "dockjax"
ENV = {**os.environ, "DOCKJAX_CACHE": str(ROOT / ".pytest-jax-cache")}
# The CLIs run on one CPU device here (their default is one per core), as the test processes
# do: the compiled programs are then those of the in-process tests with the same shapes
# (e.g. tests/test_refine.py's IMOCS run), shared through the persistent cache. Two devices
# give identical results (tests/test_xla_settings.py).
ONE_DEVICE = ["--devices", "1"]


def _run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, env=ENV, timeout=600, **kw)


def _is_png(path: Path) -> bool:
    return path.stat().st_size > 2000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def compare_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("cmp")
    r = _run([sys.executable, str(ROOT / "experiments" / "compare.py"), "--seeds", "2", "--pop", "8",
              "--iters", "3", "--presets", "paper", "--algorithms", "imocs", "nsga2", "mocs", "mopso",
              "--refine-steps", "20", "--best-known-points", "16", "--best-known-steps", "150",
              *ONE_DEVICE, "--out", str(out)])
    assert r.returncode == 0, r.stderr[-2000:]
    return out / "paper", r.stdout


def _check_every_promised_file(folder, stdout):
    for name in ("indicators.csv", "indicators.md", "runs.csv", "table3.csv", "table3.md", "table4.csv",
                 "table4.md", "chosen.json", "raw.npz"):
        assert (folder / name).stat().st_size > 0, name
    for name in ("fronts.png", "left_arm_xyz.png", "joints.png", "convergence.png"):
        assert _is_png(folder / name), name
    header = (folder / "indicators.csv").read_text().splitlines()[0].split(",")
    for ind in ("ONVG", "GD", "SP", "IGD", "HV"):
        assert f"{ind}_median" in header and f"{ind}_iqr" in header and f"{ind}_p_vs_imocs" in header
    raw = np.load(folder / "raw.npz")
    assert raw["imocs_F"].shape[:2] == (2, 8) and raw["nsga2_history"].shape == (2, 3)
    assert "wall time" in stdout
    rows = (folder / "indicators.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["imocs", "nsga2", "mocs", "mopso", "imocs+refine"]
    assert "best-known front" in (folder / "reference.txt").read_text()
    assert "best-known front" in (folder / "indicators.md").read_text()


def _hv(F, ref):
    """Plain NumPy 2-D hypervolume (minimisation), independent of dockjax."""
    F = F[np.all(F < ref, 1)]
    F = F[np.argsort(F[:, 0])]
    hv, best = 0.0, ref[1]
    for t, j in F:
        if j < best:
            hv += (ref[0] - t) * (best - j)
            best = j
    return hv


def _check_best_known_front_beats_every_run_and_is_dense_feasible(folder):
    raw = np.load(folder / "raw.npz")
    assert str(raw["reference_kind"]) == "best-known"
    best = raw["best_known_F"]
    p = DockingProblem()
    Fb, _ = p.evaluate(raw["best_known_X"])
    np.testing.assert_allclose(Fb, best, rtol=1e-12)
    _, ok = R.dense_check(p, raw["best_known_X"], n_samples=4001)
    assert np.all(ok)
    ref = np.array([61.0, 1.05 * max(best[:, 1].max(), max(raw[f"{a}_F"][..., 1].max() for a in
                                                            ("imocs", "nsga2", "mocs", "mopso")))])
    hv_best = _hv(best, ref)
    for a in ("imocs", "nsga2", "mocs", "mopso", "imocs+refine"):
        F, front = raw[f"{a}_F"], raw[f"{a}_front"]
        for i in range(F.shape[0]):
            assert _hv(F[i][front[i]], ref) <= hv_best, (a, i)
    # every algorithm's final feasible set passes the independent dense check
    for a in ("imocs", "nsga2", "mocs", "mopso", "imocs+refine"):
        X, G = raw[f"{a}_X"].reshape(-1, p.n_var), raw[f"{a}_G"].reshape(-1, p.n_con)
        feasible = np.all(G <= 0, 1)
        assert feasible.any(), a
        _, ok = R.dense_check(p, X[feasible], n_samples=4001)
        assert np.all(ok), a
    # the memetic finish improves on IMOCS run by run
    for i in range(2):
        assert _hv(raw["imocs+refine_F"][i][raw["imocs+refine_front"][i]], ref) >= \
            _hv(raw["imocs_F"][i][raw["imocs_front"][i]], ref)


def _check_chosen_trajectories_are_feasible_on_the_dense_check(folder):
    chosen = json.loads((folder / "chosen.json").read_text())
    p = DockingProblem()
    assert set(chosen) == {"compromise", "time", "smooth"}
    for c in chosen.values():
        g = R.dense_constraints(np.array(c["x"]), p.start, p.goal, p.arm_distance, p.limits[:4, 0],
                                p.limits[:4, 1], p.limits[:4, 2])
        assert np.all(g <= 0)
    assert chosen["time"]["T"] <= chosen["compromise"]["T"] <= chosen["smooth"]["T"]


def test_compare_end_to_end(compare_out):
    """One test over the one compare.py run (its three checks above), so that under ``-n 2``
    the run happens once: a module fixture used by tests on both xdist workers runs on each."""
    folder, stdout = compare_out
    _check_every_promised_file(folder, stdout)
    _check_best_known_front_beats_every_run_and_is_dense_feasible(folder)
    _check_chosen_trajectories_are_feasible_on_the_dense_check(folder)


@pytest.mark.parametrize("args, needle", [(["--seeds", "0"], "--seeds"), (["--devices", "0"], "--devices")])
def test_compare_rejects_bad_input_with_exit_2(tmp_path, args, needle):
    r = _run([sys.executable, str(ROOT / "experiments" / "compare.py"), *args, "--out", str(tmp_path / "x")])
    assert r.returncode == 2 and needle in r.stderr
    assert not (tmp_path / "x").exists()


PLAN_ARGS = ["--pop", "16", "--iters", "8", "--rate", "200", *ONE_DEVICE]
NO_REFINE = ["--refine-steps", "0"]


@pytest.fixture(scope="module")
def plan_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("plan") / "out"
    r = _run([str(SCRIPT), "plan", *PLAN_ARGS, "--out", str(out)])
    assert r.returncode == 0, r.stderr[-2000:]
    return out


def test_plan_writes_four_files_and_a_controller_ready_csv(plan_out):
    for name in ("trajectory.csv", "summary.json", "front.png", "trajectory.png"):
        assert (plan_out / name).exists(), name
    assert _is_png(plan_out / "front.png") and _is_png(plan_out / "trajectory.png")
    summary = json.loads((plan_out / "summary.json").read_text())
    data = np.loadtxt(plan_out / "trajectory.csv", delimiter=",", skiprows=1)
    header = (plan_out / "trajectory.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "t [s]" and header[7] == "d_L1 [mm]" and header[8] == "d_L1_vel [mm/s]"
    t = data[:, 0]
    assert t[-1] == pytest.approx(summary["T_s"], abs=1e-12)
    np.testing.assert_allclose(np.diff(t[:-1]), 1 / 200, atol=1e-12)
    p = DockingProblem()
    np.testing.assert_allclose(data[0, 1:7], p.start, atol=1e-9)
    np.testing.assert_allclose(data[-1, 1:7], p.goal, atol=1e-9)
    joints = data[:, 7:].reshape(len(t), 8, 4)  # position, velocity, acceleration, jerk
    for row in (0, -1):
        assert np.max(np.abs(joints[row, :, 1])) < 1e-9 and np.max(np.abs(joints[row, :, 2])) < 1e-9
    lim = p.limits
    assert np.all(np.abs(joints[:, :, 0] - p.home) <= lim[:, 0])
    assert np.all(np.abs(joints[:, :, 1]) <= lim[:, 1])
    assert np.all(np.abs(joints[:, :, 2]) <= lim[:, 2])
    # finite differences of the sampled positions match the sampled velocities
    dt = 1 / 200
    fd = (joints[2:-1, :, 0] - joints[:-3, :, 0]) / (2 * dt)
    scale = np.max(np.abs(joints[:, :, 1]), axis=0) + 1e-12
    assert np.max(np.abs(fd - joints[1:-2, :, 1]) / scale) < 1e-3
    for name, j in summary["joints"].items():
        assert j["velocity_margin"] >= 0 and j["acceleration_margin"] >= 0 and j["travel_margin"] >= 0
    assert summary["settings"]["method"] == "direct"
    assert summary["T_s"] >= summary["settings"]["shortest_T_s"] - 1e-9
    assert set(summary["explanation"]) >= {"objective", "binding"}
    assert _is_png(plan_out / "limits.png")


def test_plan_exits_1_naming_the_limit_when_the_goal_cannot_be_reached(tmp_path):
    limits = tmp_path / "limits.json"
    limits.write_text(json.dumps({"velocity": [400, 25, 0.4, 6.8]}))
    out = tmp_path / "out"
    out.mkdir()
    r = _run([str(SCRIPT), "plan", *PLAN_ARGS, *NO_REFINE, "--limits", str(limits), "--out", str(out)])
    assert r.returncode == 1, r.stderr[-2000:]
    assert "velocity" in r.stderr and ("d_L3" in r.stderr or "d_R3" in r.stderr)
    assert list(out.iterdir()) == []


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--start", "1", "2", "3", "4", "5"], "start"),
        (["--start", "775", "-35", "-1315", "nan", "-0.2", "190"], "start"),
        (["--goal", "900", "-5", "-1515", "0", "0", "180"], "stroke"),
        (["--rate", "0"], "rate"),
        (["--rate", "abc"], "rate"),
        (["--limits", "/nonexistent/limits.toml"], "limits"),
        (["--weights", "-1", "1"], "weights"),
        (["--devices", "0"], "devices"),
        (["--n-front", "1"], "n-front"),
        (["--rate", "1e9"], "rate"),
        (["--method", "simplex"], "method"),
    ],
)
def test_plan_bad_input_exits_2_and_writes_nothing(tmp_path, args, needle):
    out = tmp_path / "out"
    r = _run([str(SCRIPT), "plan", *args, "--out", str(out)])
    assert r.returncode == 2, (r.returncode, r.stderr[-500:])
    assert needle in r.stderr.lower() or needle in r.stdout.lower()
    assert not out.exists()


def test_plan_limits_file_with_a_negative_limit_exits_2(tmp_path):
    limits = tmp_path / "limits.toml"
    limits.write_text("velocity = [400, 25, -2.5, 6.8]\n")
    r = _run([str(SCRIPT), "plan", "--limits", str(limits), "--out", str(tmp_path / "out")])
    assert r.returncode == 2 and "velocity" in r.stderr
    assert not (tmp_path / "out").exists()


def test_python_api_returns_the_certified_trajectory_as_arrays():
    from dockjax.plan import plan

    # the CLI test's settings: the same compiled run, reused through the persistent cache
    p = plan(weights=(1, 0), method="imocs", pop_size=16, n_iter=8, rate=50, refine_steps=0)
    assert p.samples["position"].shape == (len(p.samples["t"]), 8)
    assert math.isclose(p.samples["t"][-1], p.T)


def test_write_plan_labels_the_front_with_the_algorithm_that_made_it(tmp_path, monkeypatch):
    import dataclasses

    from dockjax import plots
    from dockjax.plan import plan, write_plan

    p = plan(weights=(1, 0), method="imocs", pop_size=16, n_iter=8, rate=50, refine_steps=0)  # as above
    labels = []
    real = plots.plot_fronts
    monkeypatch.setattr(plots, "plot_fronts",
                        lambda fronts, *a, **k: labels.append(list(fronts)) or real(fronts, *a, **k))
    for algorithm, steps, want in (("nsga2", 0, "nsga2"), ("mopso", 300, "mopso+refine"),
                                   ("direct", 0, "least-jerk front (SQP)")):
        write_plan(dataclasses.replace(p, settings={**p.settings, "method": algorithm, "refine_steps": steps}),
                   tmp_path / algorithm)
        assert labels[-1] == [want]


def test_plan_explain_prints_the_binding_limits_with_their_checks(tmp_path):
    out = tmp_path / "out"
    r = _run([str(SCRIPT), "plan", "--select", "time", "--interval-bounds", "0.5", "10", "--explain",
              "--rate", "200", *ONE_DEVICE, "--out", str(out)])
    assert r.returncode == 0, r.stderr[-2000:]
    assert "binding limits" in r.stdout and "d_L3 velocity" in r.stdout and "re-planned" in r.stdout
    why = json.loads((out / "summary.json").read_text())["explanation"]
    row = next(b for b in why["binding"] if b["limit"] == "d_L3 velocity")
    assert row["sensitivity"] < 0
    assert row["sensitivity"] == pytest.approx(row["finite_difference"], rel=0.02)


def test_plan_limit_of_zero_exits_2(tmp_path):
    limits = tmp_path / "limits.json"
    limits.write_text(json.dumps({"acceleration": [100, 100, 0, 240]}))
    r = _run([str(SCRIPT), "plan", "--limits", str(limits), "--out", str(tmp_path / "out")])
    assert r.returncode == 2 and "acceleration" in r.stderr
    assert not (tmp_path / "out").exists()


def test_track_reproduces_the_papers_x_move_and_writes_its_files(tmp_path):
    out = tmp_path / "tr"
    r = _run([str(SCRIPT), "track", "--move", "x", "--rate", "200", "--out", str(out)])
    assert r.returncode == 0, r.stderr[-2000:]
    report = json.loads((out / "tracking.json").read_text())
    assert report["paper"] == {"joint": "d_L3", "max_position_error_mm": 0.014, "max_velocity_error_mm_s": 0.465}
    j = report["joints"]
    assert 0 < j["d_L3"]["max_position_error"] < 0.05 and 0 < j["d_L3"]["max_velocity_error"] < 1
    assert j["d_L2"]["max_position_error"] < 1e-9  # the lift joint does not move
    data = np.loadtxt(out / "tracking.csv", delimiter=",", skiprows=1)
    header = (out / "tracking.csv").read_text().splitlines()[0].split(",")
    k = header.index("d_L3 planned")
    assert data[0, k] == pytest.approx(-4.04) and data[-1, k] == pytest.approx(1.514)
    assert np.max(np.abs(data[:, k + 1] - data[:, k])) == pytest.approx(j["d_L3"]["max_position_error"], rel=1e-6)
    assert _is_png(out / "tracking.png")


@pytest.mark.parametrize("args, needle", [(["--bandwidth", "500"], "unstable"), (["--rate", "0"], "rate"),
                                          (["--move", "custom"], "--start"), (["--mass", "-1"], "mass")])
def test_track_bad_input_exits_2_and_writes_nothing(tmp_path, args, needle):
    out = tmp_path / "tr"
    r = _run([str(SCRIPT), "track", *args, "--out", str(out)])
    assert r.returncode == 2, (r.returncode, r.stderr[-800:])
    assert needle in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()
