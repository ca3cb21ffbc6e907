"""``dockjax plan`` and ``dockjax track`` in-process (``cli.main``): files, certificates,
explanations, failures. References: the dense check and finite differences of the CSV."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math

import numpy as np
import pytest

from dockjax import DockingProblem, cli
from dockjax.io import LOCK_NAME
from dockjax.problem import make_problem
from tests import reference as R

PLAN_ARGS = ["--rate", "200"]
NO_REFINE = ["--refine-steps", "0"]


def _is_png(path) -> bool:
    return path.stat().st_size > 2000 and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _main(argv):
    """``cli.main(argv)`` → (exit code, stdout)."""
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        code = cli.main(argv)
    return code, text.getvalue()


def test_plan_writes_its_files_and_a_controller_ready_csv(paper_plan):
    plan_out = paper_plan
    for name in ("trajectory.csv", "summary.json", "front.png", "trajectory.png"):
        assert (plan_out / name).exists(), name
    assert all(_is_png(plan_out / n) for n in ("front.png", "trajectory.png"))
    summary = json.loads((plan_out / "summary.json").read_text())
    # the figure of the limits' values exactly when a limit is worth something
    from dockjax.plots import worth_drawing

    assert (plan_out / "limits.png").exists() == bool(worth_drawing(summary["explanation"]))
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
    for j in summary["joints"].values():
        assert j["velocity_margin"] >= 0 and j["acceleration_margin"] >= 0 and j["travel_margin"] >= 0
    assert summary["settings"]["method"] == "direct"
    assert summary["T_s"] >= summary["settings"]["shortest_T_s"] - 1e-9
    assert set(summary["explanation"]) >= {"objective", "binding"}
    assert not [f for f in plan_out.iterdir() if f.name.startswith(".") and f.name != LOCK_NAME]


def test_plan_explain_prints_the_binding_limits_with_their_checks(wide_time_plan):
    folder, stdout = wide_time_plan
    assert "binding limits" in stdout and "d_L3 velocity" in stdout and "re-planned" in stdout
    why = json.loads((folder / "summary.json").read_text())["explanation"]
    row = next(b for b in why["binding"] if b["limit"] == "d_L3 velocity")
    assert row["sensitivity"] < 0
    assert row["sensitivity"] == pytest.approx(row["finite_difference"], rel=0.02)
    assert _is_png(folder / "limits.png")


def test_plan_exits_1_naming_the_limit_when_the_goal_cannot_be_reached(tmp_path, capsys):
    limits = tmp_path / "limits.json"
    limits.write_text(json.dumps({"velocity": [400, 25, 0.4, 6.8]}))
    out = tmp_path / "out"
    out.mkdir()
    code, _ = _main(["plan", *PLAN_ARGS, *NO_REFINE, "--limits", str(limits), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1, err
    assert "velocity" in err and ("d_L3" in err or "d_R3" in err) and "Traceback" not in err
    assert list(out.iterdir()) == []  # left as it was found


def test_a_plan_of_a_given_duration_takes_it_and_is_no_jerkier_than_the_chosen_plan_slowed_to_it(paper_plan,
                                                                                                  tmp_path):
    chosen = json.loads((paper_plan / "summary.json").read_text())
    x0, T = np.array(chosen["x"]), 1.05 * chosen["T_s"]
    out = tmp_path / "plan"
    code, text = _main(["plan", *PLAN_ARGS, "--n-front", "2", "--duration", repr(T), "--out", str(out)])
    assert code == 0, text
    s = json.loads((out / "summary.json").read_text())
    x, problem = np.array(s["x"]), make_problem("paper")
    assert s["settings"]["duration_s"] == T and "weights" not in s["settings"]
    # independent references: SciPy's B-spline for T and the jerk, dense sampling for the limits
    T_ref, J_ref = R.reference_objectives(x, problem.start, problem.goal, problem.arm_distance)
    assert T_ref == pytest.approx(T, rel=1e-12) and J_ref == pytest.approx(s["jerk"], rel=1e-8)
    _, ok = R.dense_check(problem, x[None], n_samples=40001)
    assert ok.all()
    # the compromise plan slowed to T by exact time scaling is one trajectory of that duration
    slowed = x0.copy()
    slowed[:6] *= T / chosen["T_s"]
    T_s, J_s = R.reference_objectives(slowed, problem.start, problem.goal, problem.arm_distance)
    assert T_s == pytest.approx(T, rel=1e-12) and J_ref <= J_s * (1 + 1e-9), (J_ref, J_s)
    t_last = float((out / "trajectory.csv").read_text().strip().splitlines()[-1].split(",")[0])
    assert t_last == pytest.approx(T, abs=1e-9)


def test_a_duration_below_the_shortest_time_exits_1_naming_the_binding_limit_and_the_time(wide_time_plan, tmp_path,
                                                                                          capsys):
    T_min = json.loads((wide_time_plan[0] / "summary.json").read_text())["T_s"]
    out = tmp_path / "out"
    code, _ = _main(["plan", *PLAN_ARGS, "--interval-bounds", "0.5", "10", "--duration", f"{0.97 * T_min:.4f}",
                     "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1, err
    # the lateral joints' velocity or acceleration bind the wide preset's shortest time
    assert f"{T_min:.6g}" in err and ("d_L3" in err or "d_R3" in err) and "Traceback" not in err, err
    assert not out.exists()


def test_a_plan_error_names_its_limit_as_data():
    from dockjax.plan import PlanError, plan

    slow = DockingProblem(velocity=[400, 25, 0.4, 6.8])
    with pytest.raises(PlanError) as info:
        plan(slow, check_sensitivities=False)
    e = info.value
    assert e.joint in ("d_L3", "d_R3") and e.quantity == "velocity" and e.limit == 0.4 and e.unit == "mm/s"
    assert e.excess > 0 and e.joint in str(e)
    # within the floor (30 mm at 0.6 mm/s: 50 s) but not for the straight line slowed to the
    # longest T, the diagnosis after a failed solve: the straight line's need, from a dense check
    from dockjax.solve import infeasibility, straight_line

    p = DockingProblem(velocity=[400, 25, 0.6, 6.8])
    e = infeasibility(p)
    x = straight_line(p, [60.0])[0]
    g = R.dense_constraints(x, p.start, p.goal, p.arm_distance, *np.asarray(p.limits).T, n_samples=20001)
    need = g.reshape(8, 3)[2, 1] + 1  # d_L3's velocity over its limit at T = 60 s
    assert (e.joint, e.quantity, e.limit) == ("d_L3", "velocity", 0.6) and e.excess > 0
    import re

    stated = float(re.search(r"T >= ([\d.]+) s", str(e)).group(1))  # a certified (screened) need: never below
    assert 60 * need * (1 - 1e-3) <= stated <= 60 * need * 1.01, (str(e), 60 * need)


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--start", "1", "2", "3", "4", "5"], "--start"),
        (["--start", "775", "-35", "-1315", "nan", "-0.2", "190"], "--start"),
        (["--goal", "900", "-5", "-1515", "0", "0", "180"], "stroke"),
        (["--rate", "0"], "--rate"),
        (["--rate", "abc"], "--rate"),
        (["--limits", "/nonexistent/limits.toml"], "limits"),
        (["--weights", "-1", "1"], "--weights"),
        (["--devices", "0"], "--devices"),
        (["--n-front", "1"], "--n-front"),
        (["--rate", "1e9"], "--rate"),
        (["--method", "simplex"], "--method"),
        (["--seed", str(2**70)], "--seed"),
        (["--pop", "3", "--method", "imocs"], "--pop"),
        (["--duration", "61"], "--duration"),  # longer than 6 x 10 s, the paper's interval bounds
        (["--duration", "-1"], "--duration must be finite and > 0, got -1.0"),
        (["--duration", "nan"], "--duration must be finite and > 0, got nan"),
    ],
)
def test_plan_bad_input_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, args, needle):
    out = tmp_path / "out"
    code, _ = _main(["plan", *args, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2, (code, err)
    assert needle in err and err.startswith("error: ") and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


@pytest.mark.parametrize("limits, needle", [("velocity = [400, 25, -2.5, 6.8]\n", "velocity"),
                                            ('{"acceleration": [100, 100, 0, 240]}', "acceleration")])
def test_plan_limits_file_with_a_bad_limit_exits_2(tmp_path, capsys, limits, needle):
    path = tmp_path / "limits.txt"
    path.write_text(limits)
    code, _ = _main(["plan", "--limits", str(path), "--out", str(tmp_path / "out")])
    assert code == 2 and needle in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_python_api_returns_the_certified_trajectory_as_arrays(imocs_plan):
    p = imocs_plan
    assert p.samples["position"].shape == (len(p.samples["t"]), 8)
    assert math.isclose(p.samples["t"][-1], p.T)
    assert repr(p).startswith("Plan(T=") and len(repr(p)) < 300


def test_write_plan_labels_the_front_with_the_algorithm_that_made_it(imocs_plan, tmp_path, monkeypatch):
    from dockjax import plots
    from dockjax.plan import write_plan

    labels = []
    real = plots.plot_fronts
    monkeypatch.setattr(plots, "plot_fronts",
                        lambda fronts, *a, **k: labels.append(list(fronts)) or real(fronts, *a, **k))
    for algorithm, steps, want in (("nsga2", 0, "nsga2"), ("mopso", 300, "mopso+refine"),
                                   ("direct", 0, "least-jerk front (SQP)")):
        p = dataclasses.replace(imocs_plan, settings={**imocs_plan.settings, "method": algorithm,
                                                      "refine_steps": steps})
        write_plan(p, tmp_path / algorithm)
        assert labels[-1] == [want]


def test_track_reproduces_the_papers_x_move_and_writes_its_files(tmp_path):
    out = tmp_path / "tr"
    code, stdout = _main(["track", "--move", "x", "--rate", "200", "--out", str(out)])
    assert code == 0
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
    assert report["model"]["mass"] == 1.0 and "d_L3" in stdout


@pytest.mark.parametrize("args, needle", [(["--bandwidth", "500"], "unstable"), (["--rate", "0"], "--rate"),
                                          (["--move", "custom"], "--start"), (["--mass", "-1"], "--mass"),
                                          (["--velocity-filter", "-1"], "--velocity-filter")])
def test_track_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, args, needle):
    out = tmp_path / "tr"
    code, _ = _main(["track", *args, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2, (code, err)
    assert needle in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_plan_shows_each_step_when_asked(capfd, monkeypatch):
    """``plan(progress=True)``: a bar on stderr naming the step under way, counting the
    shortest time, each of the front's caps, the certificate and the explanation."""
    from dockjax import plan as plan_module

    closed = []

    class Bar(plan_module.tqdm):  # records the count each bar reached when it closed
        def close(self):
            closed.append(self.n)
            super().close()

    monkeypatch.setattr(plan_module, "tqdm", Bar)
    p = plan_module.plan(weights=(1, 0), n_front=2, rate=50, check_sensitivities=False, progress=True)
    err = capfd.readouterr().err
    assert p.T > 0 and set(closed) == {5}, closed  # shortest time, 2 caps, certificate, explanation
    for step in ("shortest time", "least jerk at 2 time caps", "certifying"):
        assert step in err, err[-800:]
