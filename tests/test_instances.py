"""Moves as the instances of a study (dockjax.instances, ``dockjax sweep --instances``).

References written here: the inverse kinematics of tests/reference.py (for the travel and
home checks), each joint's bang-bang time floor, SciPy's Friedman test on a matrix built
from runs.csv, and moocore's hypervolume of every run's front normalised by its own
instance's reference. The sweep is the tests' tiny study (tests/sweeps.py: pop 8, 3
iterations, the same compiled program) on two moves near the paper's.
"""

from __future__ import annotations

import csv
import json
import re
import signal

import moocore
import numpy as np
import pytest
from scipy.stats import friedmanchisquare, kendalltau

from dockjax import config, sweep
from dockjax.instances import (
    WORKSPACE,
    Instance,
    Workspace,
    check_instances,
    instances_text,
    load_instances,
    parse_instances,
    random_instances,
)
from dockjax.problem import DockingProblem
from tests import reference as R
from tests import sweeps as S

TWO_MOVES = """
[[instance]]
name = "paper"
start = [775, -35, -1315, 0.2, -0.2, 190]
goal = [745, -5, -1515, 0, 0, 180]

[[instance]]
name = "slow lift"
start = [770.5, -30, -1300, 0.1, -0.1, 188]
goal = [750, -10, -1500, 0, 0, 181]
arm_distance = 2000
[instance.limits]
velocity = [400, 20, 2.5, 6.8]
"""


@pytest.fixture
def two_moves(tmp_path):
    path = tmp_path / "moves.toml"
    path.write_text(TWO_MOVES)
    return path


def test_a_file_of_instances_gives_their_problems_over_the_preset(two_moves):
    a, b = load_instances(two_moves)
    assert (a.name, b.name) == ("paper", "slow lift")
    pa, pb = check_instances([a, b], "wide")
    assert np.array_equal(pa.start, config.START) and np.array_equal(pa.goal, config.GOAL)
    assert pa.interval_bounds == config.PRESETS["wide"]["interval_bounds"] == pb.interval_bounds
    assert np.asarray(pb.limits)[[1, 5], 1].tolist() == [20.0, 20.0]  # the lift joints of both arms
    assert np.asarray(pb.limits)[2, 1] == 2.5
    # home: the midpoint of the instance's own start and goal joints
    mid = 0.5 * (R.joints_of_pose(pb.start, 2000.0) + R.joints_of_pose(pb.goal, 2000.0))
    np.testing.assert_allclose(pb.home, mid, rtol=0, atol=1e-9)
    assert Instance("x", {"start": list(config.START), "goal": list(config.GOAL)}).problem().identity() == \
        DockingProblem().identity()


def test_instances_written_as_text_read_back_the_same(two_moves, tmp_path):
    moves = load_instances(two_moves) + random_instances(3, seed=4)
    path = tmp_path / "back.toml"
    path.write_text(instances_text(moves))
    assert load_instances(path) == moves


@pytest.mark.parametrize("text, message", [
    ("x = 1", "unknown key(s) ['x']"),
    ("", "holds no [[instance]] table"),
    ("[[instance]]\nstart = [1, 2, 3, 4, 5, 6]", "instance 0: goal is missing"),
    ("[[instance]]\nname = 'a'\nstart = [1, 2, 3]\ngoal = [1, 2, 3, 4, 5, 6]", "instance 0 ('a'): start must be 6"),
    ("[[instance]]\nstart = [1, 2, 3, 4, 5, 6]\ngoal = [1, 2, 3, 4, 5, 6]\nspeed = 2", "unknown key(s) ['speed']"),
    ("[[instance]]\nstart = [1, 2, 3, 4, 5, 6]\ngoal = [1, 2, 3, 4, 5, 6]\nn_control = 0", "n_control must be"),
    ("[[instance]]\nstart = [1, 2, 3, 4, 5, 6]\ngoal = [1, 2, 3, 4, 5, 6]\n[instance.limits]\nspeed = [1]",
     "limits: unknown key(s) ['speed']"),
    ("[[instance]]\nname = 'a'\nstart = [1, 2, 3, 4, 5, 6]\ngoal = [1, 2, 3, 4, 5, 7]\n"
     "[[instance]]\nname = 'a'\nstart = [1, 2, 3, 4, 5, 6]\ngoal = [1, 2, 3, 4, 5, 7]", "['a'] repeated"),
    ("[[instance]\n", "is not valid TOML"),
])
def test_a_bad_file_is_refused_naming_the_instance(tmp_path, text, message):
    path = tmp_path / "moves.toml"
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        load_instances(path)
    assert message in str(info.value) and str(path) in str(info.value)


def test_moves_that_are_bad_input_are_named_before_any_solve():
    same = Instance("still", {"start": list(config.START), "goal": list(config.START)})
    with pytest.raises(ValueError, match="instance 'still': start and goal are the same pose"):
        check_instances([same])
    far = Instance("far", {"start": list(config.START), "goal": [615.0, -5.0, -1515.0, 0.0, 0.0, 180.0]})
    with pytest.raises(ValueError, match="instance 'far': .*d_L3"):  # 160 mm lateral at 2.5 mm/s: over 60 s
        check_instances([far])
    with pytest.raises(ValueError, match="instances random:N needs a whole number"):
        parse_instances("random:x")
    with pytest.raises(ValueError, match="instances must be an integer from 1"):
        parse_instances("random:0")


def _floor(p: DockingProblem) -> float:
    d = np.abs(R.joints_of_pose(p.goal, p.arm_distance) - R.joints_of_pose(p.start, p.arm_distance))
    v, a = np.asarray(p.limits)[:, 1], np.asarray(p.limits)[:, 2]
    return float(np.where(d >= v * v / a, d / v + v / a, 2 * np.sqrt(d / a)).max())


def test_random_moves_are_seeded_inside_the_workspace_and_feasible():
    moves = random_instances(40, seed=11, preset="wide")
    assert moves == random_instances(40, seed=11, preset="wide")
    assert moves[:5] == random_instances(5, seed=11, preset="wide")  # the k-th move depends on the seed alone
    assert moves[:5] != random_instances(5, seed=12, preset="wide")
    assert len({m.name for m in moves}) == 40
    travel = np.asarray(DockingProblem().limits)[:, 0]
    for m, p in zip(moves, check_instances(moves, "wide")):
        for key, centre in (("start", WORKSPACE.start), ("goal", WORKSPACE.goal)):
            off = np.abs(np.asarray(m.fields[key]) - centre)
            assert np.all(off <= np.asarray(WORKSPACE.spread) + 1e-9), (m.name, key)
        move = np.abs(R.joints_of_pose(p.goal, p.arm_distance) - R.joints_of_pose(p.start, p.arm_distance))
        assert np.all(move <= 2 * WORKSPACE.travel_use * travel + 1e-9), m.name
        assert _floor(p) <= p.n_intervals * p.interval_bounds[1]
    attitude = np.array([np.abs(np.subtract(m.fields["goal"], m.fields["start"]))[3:5] for m in moves])
    assert attitude.max() > 1.0  # attitude moves of degrees, not the paper's tenths


def test_a_workspace_no_move_can_meet_is_refused():
    narrow = Workspace(goal=(645.0, -35.0, -1315.0, 0.2, -0.2, 190.0), spread=(0.0,) * 6)  # 130 mm lateral
    with pytest.raises(ValueError, match="no move that meets the checks"):
        random_instances(2, seed=0, workspace=narrow)


def _runs(out) -> list[dict]:
    with open(out / "runs.csv", newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def study(run_once, tmp_path_factory):
    def make(folder):
        path = folder / "moves.toml"
        path.write_text(TWO_MOVES)
        out = folder / "study"
        code, text = S.run(out, S.TINY, "--rho", "0.3", "0.5", "0.7", "--alpha-max", "0.1", "--instances", str(path))
        return code, text, out, path

    return run_once("instances-study", make)


def test_a_study_over_instances_runs_every_setting_and_seed_on_each(study):
    code, text, out, _ = study
    assert code == 0, text
    rows = _runs(out)
    assert list(rows[0])[:7] == ["setting", "algorithm", "pop", "iterations", "params", "seed", "instance"]
    runs = {(r["setting"], r["instance"], r["seed"]) for r in rows}
    assert len(rows) == len(runs) == 3 * 2 * 2
    assert {r["instance"] for r in rows} == {"paper", "slow lift"}
    refs = [np.load(out / "references" / f"instance-{k:05d}.npz") for k in range(2)]
    assert not np.array_equal(refs[0]["front"], refs[1]["front"])  # each instance has its own reference
    ident = json.loads((out / "config.json").read_text())["identity"]
    assert [i["name"] for i in ident["instances"]] == ["paper", "slow lift"]
    md = (out / "report.md").read_text()
    assert "## Per instance" in md and "2 instances" in md and (out / "hv_per_instance.png").stat().st_size > 0


def test_each_runs_hypervolume_is_against_its_own_instances_reference(study):
    _, _, out, _ = study
    fronts = np.load(out / "fronts.npz")
    rows = _runs(out)
    refs = [np.load(out / "references" / f"instance-{k:05d}.npz") for k in range(2)]
    names = ["paper", "slow lift"]
    assert len(rows) == len(fronts["offsets"]) - 1
    for i, r in enumerate(rows):  # both files sorted by (setting, instance, seed)
        k = int(fronts["instance"][i])
        assert names[k] == r["instance"] and int(fronts["seed"][i]) == int(r["seed"])
        F = fronts["F"][fronts["offsets"][i]:fronts["offsets"][i + 1]]
        ideal, nadir = refs[k]["ideal"], refs[k]["nadir"]
        hv = moocore.hypervolume((F - ideal) / (nadir - ideal), ref=[float(refs[k]["hv_ref"])] * 2) if len(F) else 0.0
        assert float(r["HV"]) == pytest.approx(hv, rel=1e-9, abs=1e-12), (i, r["instance"])


def test_the_friedman_test_blocks_are_instance_and_seed_pairs(study):
    _, _, out, _ = study
    rows = _runs(out)
    blocks = sorted({(r["instance"], r["seed"]) for r in rows})
    M = np.full((3, len(blocks)), np.nan)
    for r in rows:
        M[int(r["setting"]), blocks.index((r["instance"], r["seed"]))] = float(r["HV"])
    assert len(blocks) == 4 and np.isfinite(M).all()
    p = friedmanchisquare(*M).pvalue
    stated = re.search(r"Friedman test across the 3 compared settings: p = ([0-9][0-9.e-]*[0-9]|n/a)",
                       (out / "report.md").read_text()).group(1)
    assert "4 blocks (instance, seed)" in (out / "report.md").read_text()
    if stated != "n/a":
        assert float(stated) == pytest.approx(p, rel=2e-3)  # printed to three digits


def test_the_same_command_resumes_and_other_instances_are_refused(study, capsys):
    code, text, out, path = study
    again, said = S.run(out, S.TINY, "--rho", "0.3", "0.5", "0.7", "--alpha-max", "0.1", "--instances", str(path))
    assert again == 0 and "6 of 6 chunks already done" in said, said
    refused, _ = S.run(out, S.TINY, "--rho", "0.3", "0.5", "0.7", "--alpha-max", "0.1", "--instances", "random:2")
    assert refused == 2 and "instances" in capsys.readouterr().err


@pytest.mark.parametrize("extra, message", [
    (["--instances", "random:0"], "instances must be an integer from 1"),
    (["--instances", "nowhere.toml"], "instances file nowhere.toml cannot be read"),
    (["--instances", "random:2", "--reference-front", "front.csv"], "takes each instance's own reference"),
])
def test_bad_instances_exit_2_with_one_line_and_no_folder(tmp_path, capsys, extra, message):
    out = tmp_path / "new"
    code, _ = S.run(out, S.TINY, *extra)
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


def test_a_study_without_instances_keeps_its_identity():
    cfg = sweep.make_config(algorithms=("imocs",), pop=(8,), iters=(3,), seeds=2, chunk=2, reference="pilot")[0]
    assert sorted(cfg.identity()) == ["chunk", "devices", "driver", "format", "hv_ref", "normalisation", "preset",
                                      "race", "reference", "seeds", "settings"]
    assert cfg.identity()["normalisation"] == "ideal and nadir of reference.npz's front"
    assert {spec.instance for spec in sweep.plan_round(cfg, 0, [True], range(2))} == {-1}


HELD_OUT = """
[[instance]]
name = "held out a"
start = [772, -33, -1310, 0.15, -0.15, 189]
goal = [748, -8, -1510, 0, 0, 181]

[[instance]]
name = "held out b"
start = [778, -37, -1320, 0.2, -0.1, 190]
goal = [741, -3, -1520, 0.05, 0, 179]
"""


@pytest.fixture(scope="module")
def tested(run_once):
    def make(folder):
        train, test = folder / "moves.toml", folder / "held_out.toml"
        train.write_text(TWO_MOVES)
        test.write_text(HELD_OUT)
        argv = [S.TINY, "--rho", "0.3", "0.5", "0.7", "--alpha-max", "0.1", "--instances", str(train),
                "--test-instances", str(test)]
        out = folder / "study"
        code, text = S.run(out, *argv)
        return code, text, out, argv

    return run_once("test-set-study", make)


def _median(rows, setting_label, column):
    return float(np.median([float(r[column]) for r in rows if r["params"] == setting_label]))


def test_the_best_and_the_tied_settings_run_on_the_held_out_moves(tested):
    code, text, out, _ = tested
    assert code == 0, text
    with open(out / "summary.csv", newline="") as f:
        elites = {r["params"] for r in csv.DictReader(f) if r["status"] in ("best", "tied")}
    test_rows = _runs(out / "test")
    assert {r["params"] for r in test_rows} == elites and elites
    assert {r["instance"] for r in test_rows} == {"held out a", "held out b"}
    assert {r["seed"] for r in test_rows} == {"0", "1"} and len(test_rows) == len(elites) * 2 * 2
    assert (out / "test" / "references" / "instance-00001.npz").exists()


def test_the_report_compares_training_and_test_medians(tested):
    _, _, out, _ = tested
    train_rows, test_rows = _runs(out), _runs(out / "test")
    md = (out / "report.md").read_text()
    section = md[md.index("## Test set"):]
    labels = sorted({r["params"] for r in test_rows})
    tr = np.array([_median(train_rows, p, "HV") for p in labels])
    te = np.array([_median(test_rows, p, "HV") for p in labels])
    for p, a, b in zip(labels, tr, te):  # the table's row of each setting: train then test median HV
        rho = dict(kv.split("=") for kv in p.split())["rho"]  # runs.csv: "alpha_max=0.1 rho=0.3"
        row = next(line for line in section.splitlines() if line.startswith("| imocs") and f"ρ={rho} |" in line)
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert float(cells[1]) == pytest.approx(a, abs=5e-5) and float(cells[2]) == pytest.approx(b, abs=5e-5)
    if len(labels) >= 3:
        tau = kendalltau(tr, te).statistic
        stated = float(re.search(r"Kendall's τ between the training and test orders by median HV: (-?[0-9.]+)",
                                 section).group(1))
        assert stated == pytest.approx(tau, abs=0.006)
    assert ("the ranking held" in section) != ("ranking did not hold" in section)
    assert (out / "hv_train_test.png").stat().st_size > 0


def test_a_test_set_resumes_and_must_be_held_out(tested, tmp_path, capsys):
    _, _, out, argv = tested
    again, said = S.run(out, *argv)
    assert again == 0 and said.count("chunks already done") == 2, said
    train = next(a for a in argv[1:] if a.endswith("moves.toml"))
    code, _ = S.run(tmp_path / "x", S.TINY, "--instances", train, "--test-instances", train)
    assert code == 2 and "are training moves too" in capsys.readouterr().err
    assert parse_instances("random:2", seed=5, skip=3) == random_instances(5, seed=5)[3:]



@pytest.fixture(scope="module")
def instance_race(run_once):
    def make(folder):
        path = folder / "moves.toml"
        path.write_text(TWO_MOVES)
        extra = ("--instances", str(path), "--seeds", "3")
        out = folder / "race"
        code, text = S.run(out, S.RACE, *extra)
        return code, text, out, extra

    return run_once("instance-race", make)


def test_a_race_over_instances_brings_new_instances_each_round(instance_race):
    """irace's order: every instance with seed 0, then every instance with seed 1, ...:
    each setting's runs are a prefix of that order, as long as the setting survived."""
    code, text, out, _ = instance_race
    assert code == 0, text
    order = [(k, s) for s in range(3) for k in ("paper", "slow lift")]
    rows = _runs(out)
    for setting in {r["setting"] for r in rows}:
        done = {(r["instance"], int(r["seed"])) for r in rows if r["setting"] == setting}
        assert done == set(order[:len(done)]) and len(done) >= 2, (setting, sorted(done))
    md = (out / "report.md").read_text()
    assert "| round | blocks (instance, seed) so far | settings left |" in md


def test_an_interrupted_instance_race_resumes_to_the_same_table(instance_race, tmp_path):
    _, _, full, extra = instance_race
    out = tmp_path / "killed"
    # kill after round 0 (4 settings x 2 blocks in 4 chunks) and the first chunk of round 1
    assert S.process(out, S.argv(S.RACE, *extra), "SIGKILL:5").returncode == -signal.SIGKILL
    assert len(list((out / "chunks").glob("round-*.npz"))) == 5
    assert S.run(out, S.RACE, *extra)[0] == 0
    assert S.table(out) == S.table(full)
