"""Resumable hyper-parameter studies (dockjax.sweep, ``dockjax sweep``, experiments/sweep.py).

Tiny settings throughout (pop 8, 3 iterations, 2 × 2 grid, 2 seeds, chunks of 2 → 4 chunks;
the reference a pilot, so no best-known front is computed). The command runs in this
process (``cli.main``); a real process only where the test is about one: ``kill -9`` and
Ctrl-C (the sweep signals itself after a given chunk, ``DOCKJAX_SWEEP_SIGNAL``) and the
console script.
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dockjax import cli, sweep
from dockjax.io import LOCK_NAME
from dockjax.sweep.config import PILOT_SEED0, round_seeds
from tests import sweeps as S
from tests.sweeps import RACE, TINY

FIGURES = ("heatmap_hv_imocs_pop8_it3.png", "anytime_hv.png", "eaf.png", "fronts_best_worst.png")


def _main(argv: list[str]) -> int:
    return cli.main(["sweep", *argv])


_run, _process, _table = S.run, S.process, S.table


def test_end_to_end_writes_table_report_and_figures(tiny_sweep):
    uninterrupted = tiny_sweep
    out, stdout = uninterrupted
    rows = _table(out)
    assert rows[0] == list(sweep.COLUMNS[:-1])
    assert len(rows) == 1 + 8
    body = [dict(zip(rows[0], r)) for r in rows[1:]]
    keys = [(int(r["setting"]), int(r["seed"])) for r in body]
    assert keys == sorted(keys) and len(set(keys)) == 8  # sorted, every run once
    assert all(r["algorithm"] == "imocs" and r["pop"] == "8" and r["iterations"] == "3" for r in body)
    hv = np.array([float(r["HV"]) for r in body])
    assert np.all(np.isfinite(hv)) and np.all(hv >= 0)
    assert sorted(p.name for p in (out / "chunks").iterdir()) == [f"round-000-chunk-{i:05d}.npz" for i in range(4)]
    for name in ("config.json", "reference.npz", "summary.csv", "summary.md", "report.md", "fronts.npz", *FIGURES):
        assert (out / name).stat().st_size > 0, name
    assert not [p for p in out.rglob(".*") if p.name != LOCK_NAME], "temporary files left behind"
    fronts = np.load(out / "fronts.npz")
    assert fronts["offsets"][-1] == len(fronts["F"]) == len(fronts["X"]) and len(fronts["setting"]) == 8
    header = (out / "summary.csv").read_text().splitlines()[0].split(",")
    for col in ("HV_ci_low", "HV_ci_high", "IGD+_ci_low", "p_holm", "A12_best_over", "tied_with_best", "status"):
        assert col in header
    # two seeds cannot tell four settings apart: no winner is crowned
    assert "cannot name a winner" in stdout and "tied" in stdout
    report = (out / "report.md").read_text()
    assert "## Verdict" in report and "![eaf](eaf.png)" in report


def test_kill_and_resume_gives_the_same_table(tiny_sweep, tmp_path):
    full, _ = tiny_sweep
    out = tmp_path / "killed"
    killed = _process(out, signal_after="SIGKILL:1")
    assert killed.returncode == -signal.SIGKILL
    before = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (out / "chunks").glob("round-*.npz")}
    assert len(before) == 1 and not (out / "runs.csv").exists()
    code, stdout = _run(out)
    assert code == 0
    assert "resuming, 1 of 4 chunks already done" in stdout
    after = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (out / "chunks").glob("round-*.npz")}
    assert len(after) == 4
    assert {k: after[k] for k in before} == before  # chunks finished before the kill were not rewritten
    assert _table(out) == _table(full)


def test_ctrl_c_exits_130_without_a_traceback_and_the_sweep_resumes(tiny_sweep, tmp_path):
    full, _ = tiny_sweep
    out = tmp_path / "interrupted"
    r = _process(out, signal_after="SIGINT:2")
    assert r.returncode == 130, r.stderr[-800:]
    assert "Traceback" not in r.stderr and "2 finished chunks are saved" in r.stderr
    assert len(list((out / "chunks").glob("round-*.npz"))) == 2 and not (out / "runs.csv").exists()
    assert not [p for p in out.rglob(".*") if p.name.endswith(".tmp")]
    assert _run(out)[0] == 0
    assert _table(out) == _table(full)


def test_a_race_resumed_after_a_kill_equals_an_uninterrupted_race(tiny_race, tmp_path):
    full, stdout = tiny_race
    assert "round 0: seeds 0..1" in stdout
    out = tmp_path / "killed"
    # kill after round 0 (4 chunks) and the first chunk of round 1 are written
    assert _process(out, RACE, signal_after="SIGKILL:5").returncode == -signal.SIGKILL
    assert len(list((out / "chunks").glob("round-*.npz"))) == 5
    assert _run(out, RACE)[0] == 0
    assert _table(out) == _table(full)
    assert (out / "summary.csv").read_text() == (full / "summary.csv").read_text()
    assert sorted(p.name for p in (out / "chunks").iterdir()) == sorted(p.name for p in (full / "chunks").iterdir())


def test_dask_backend_gives_the_same_table(tiny_sweep, tmp_path):
    pytest.importorskip("distributed")
    full, _ = tiny_sweep
    out = tmp_path / "dask"
    assert _run(out, TINY, "--backend", "dask", "--workers", "2")[0] == 0
    assert _table(out) == _table(full)
    # a cluster of threads runs in this process, on its devices: the study records them
    assert sweep.load_config(out).devices == sweep.load_config(full).devices == 1


def test_a_folder_with_another_configuration_is_refused(tiny_sweep, capsys):
    out, _ = tiny_sweep
    listing = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.name != LOCK_NAME}
    code = _main([*S.argv(TINY, "--rho", "0.3"), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert "different sweep configuration" in err and "settings" in err and len(err.strip().splitlines()) == 1
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.name != LOCK_NAME} == listing
    assert _main([*S.argv(TINY, "--chunk", "3"), "--out", str(out)]) == 2
    assert "chunk" in capsys.readouterr().err


def test_a_folder_resumes_only_with_its_device_count(tmp_path):
    cfg, _ = sweep.make_config(pop=(8,), iters=(3,), seeds=1, reference="pilot", devices=1)
    sweep.prepare_folder(tmp_path / "s", cfg)
    (tmp_path / "s" / "config.json").write_text('{"identity": ' + __import__("json").dumps(cfg.identity()) + "}")
    other, _ = sweep.make_config(pop=(8,), iters=(3,), seeds=1, reference="pilot", devices=2)
    with pytest.raises(sweep.ConfigError, match=r"made on 1 CPU device\(s\), this command runs them on 2"):
        sweep.prepare_folder(tmp_path / "s", other)


@pytest.mark.parametrize("extra, message", [
    (["--rho", "0.3", "1.5"], "rho (ρ) must be a number in (0, 1)"),
    (["--rho", "0"], "rho (ρ) must be a number in (0, 1)"),
    (["--alpha-max", "0"], "alpha_max (α_max) must be a number > 0"),
    (["--pop", "3"], "--pop values must be >= 4"),
    (["--rho"], "--rho grid is empty"),
    (["--pop"], "--pop grid is empty"),
    (["--seeds", "0"], "--seeds must be >= 1"),
    (["--refine-steps", "-1"], "--refine-steps must be >= 0"),
    (["--scheduler", "tcp://localhost:1"], "--scheduler needs --backend dask"),
    (["--devices", "0"], "--devices must be an integer >= 1"),
    (["--param", "imocs.sigma=0.3"], "unknown hyper-parameter for imocs; allowed: alpha_max, p_a, rho"),
    (["--param", "p_a=1.5"], "p_a (p_a) must be a number in [0, 1]"),
    (["--param", "rho"], "expected NAME=VALUES"),
    (["--param", "rho=a,b"], "VALUES must be numbers"),
    (["--param", "p_a=0_1"], "VALUES must be numbers"),
    (["--param", "cuckoo.rho=0.3"], "'cuckoo' is not an algorithm"),
    (["--rho", "0.3", "--rho", "0.4"], "--rho is given twice"),
    (["--param", "p_a=0.1:0.3"], "is a range: sample it with --design random or sobol"),
    (["--algorithm", "mopso", "--param", "mopso.n_div=2.5"], "n_div (divisions) must be an integer >= 1"),
    (["--param", "nsga2.eta_c=10"], "nsga2 is not among --algorithm"),
    (["--param", "pop_size=4"], "set by --pop, --iters and --budget"),
    (["--budget", "4"], "--budget 4 gives no iteration at --pop [8]"),
    (["--rho", "0.4", "--param", "rho=0.3"], "--rho and --param rho both give rho"),
])
def test_bad_input_exits_2_before_compiling_and_leaves_no_folder(tmp_path, capsys, extra, message):
    out = tmp_path / "new" / "sweep"
    code = _main([*S.argv(TINY, *extra), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.startswith("error: ") and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "new").exists()


def test_unwritable_folder_exits_2(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    assert _main([*TINY, "--out", str(blocker / "sweep")]) == 2
    assert "cannot be created" in capsys.readouterr().err
    assert _main([*TINY, "--out", str(blocker)]) == 2
    assert "is not a folder" in capsys.readouterr().err
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("x")
    assert _main([*TINY, "--out", str(other)]) == 2
    assert "holds no sweep" in capsys.readouterr().err
    assert sorted(p.name for p in other.iterdir()) == ["notes.txt"]


def test_the_console_script_exits_2_with_one_line_for_an_unknown_parameter(tmp_path):
    out = tmp_path / "x"
    proc = subprocess.run([str(Path(sys.executable).parent / "dockjax"), "sweep", "--param", "imocs.beta=2", "--out",
                           str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "error: --param beta: unknown hyper-parameter for imocs; allowed: alpha_max, p_a, rho"]
    assert not out.exists()


def _cfg(**kw) -> sweep.SweepConfig:
    base = dict(algorithms=("imocs",), params=[sweep.ParamSpec("rho", "imocs", values=(0.3, 0.5)),
                                               sweep.ParamSpec("alpha_max", "imocs", values=(0.1, 0.2))],
                pop=(8,), iters=(3,), seeds=2, chunk=2, reference="pilot")
    return sweep.make_config(**{**base, **kw})[0]


def test_plan_is_balanced_padded_and_deterministic():
    cfg = _cfg(pop=(8, 12), params=[sweep.ParamSpec("rho", "imocs", values=(0.3, 0.4, 0.5)),
                                    sweep.ParamSpec("alpha_max", "imocs", values=(0.05, 0.1, 0.2))], chunk=16)
    alive = np.ones(len(cfg.settings), bool)
    plan = sweep.plan_round(cfg, 0, alive, round_seeds(cfg, 0, 0, len(alive)))
    assert [(c.pop, len(c.seeds), c.n_real) for c in plan] == [(8, 9, 9), (8, 9, 9), (12, 9, 9), (12, 9, 9)]
    runs = sorted((s, k) for c in plan for s, k in zip(c.settings[:c.n_real], c.seeds[:c.n_real]))
    assert runs == [(s, k) for s in range(18) for k in range(2)]
    assert plan == sweep.plan_round(cfg, 0, alive, round_seeds(cfg, 0, 0, len(alive)))
    # every run carries its own hyper-parameters
    c = plan[0]
    params = c.params()
    for j in range(c.n_real):
        setting = dict(cfg.settings[c.settings[j]].params)
        assert dict(c.hyper[j]) == setting
        assert (params.rho[j], params.alpha_max[j]) == (setting["rho"], setting["alpha_max"])
    odd = _cfg(params=[sweep.ParamSpec("alpha_max", "imocs", values=(0.1, 0.2, 0.3))], seeds=1)
    plan = sweep.plan_round(odd, 0, np.ones(3, bool), range(1))
    assert [(len(c.seeds), c.n_real) for c in plan] == [(2, 2), (2, 1)]
    assert plan[-1].seeds == (0, 0) and list(plan[-1].params().alpha_max) == [0.3, 0.3]  # padded with its own run
    pilot = sweep.pilot_spec(cfg)
    assert pilot.pop == 12 and min(pilot.seeds) >= PILOT_SEED0 and set(pilot.hyper) == {()}


def test_race_rounds_fill_a_chunk_with_the_survivors():
    cfg = _cfg(seeds=31, chunk=40, race=True, race_min_seeds=5)
    assert round_seeds(cfg, 0, 0, 25) == range(5)
    assert round_seeds(cfg, 1, 5, 5) == range(5, 13)  # 40 // 5 seeds for 5 survivors
    assert round_seeds(cfg, 2, 29, 5) == range(29, 31)  # capped at the budget
    assert round_seeds(cfg, 1, 5, 60) == range(5, 6)  # at least one seed
    alive = np.zeros(len(cfg.settings), bool)
    alive[:2] = True
    plan = sweep.plan_round(cfg, 1, alive, range(5, 13))
    assert all(len(c.seeds) == 40 for c in plan)  # one compiled shape for every round of a race


def test_designs_grid_samples_budget_and_head_to_head():
    P = sweep.ParamSpec
    specs = [P("p_a", None, values=(0.1, 0.2)), P("eta_c", "nsga2", values=(5, 15))]
    s = sweep.build_settings(["imocs", "nsga2"], specs, pops=(50, 100), iters=(10,))
    # p_a applies to IMOCS only (NSGA-II has no p_a); eta_c to NSGA-II
    assert [(x.algorithm, x.pop, x.params) for x in s] == [
        ("imocs", 50, (("p_a", 0.1),)), ("imocs", 50, (("p_a", 0.2),)), ("imocs", 100, (("p_a", 0.1),)),
        ("imocs", 100, (("p_a", 0.2),)), ("nsga2", 50, (("eta_c", 5.0),)), ("nsga2", 50, (("eta_c", 15.0),)),
        ("nsga2", 100, (("eta_c", 5.0),)), ("nsga2", 100, (("eta_c", 15.0),))]
    budget = sweep.build_settings(["mocs"], [], pops=(50, 100, 150), budget=15000)
    assert [(x.pop, x.iters) for x in budget] == [(50, 300), (100, 150), (150, 100)]
    a = sweep.build_settings(["imocs"], [P("rho", None, lo=0.1, hi=0.9)], pops=(8,), iters=(3,), design="sobol",
                             samples=8, seed=3)
    b = sweep.build_settings(["imocs"], [P("rho", None, lo=0.1, hi=0.9)], pops=(8,), iters=(3,), design="sobol",
                             samples=8, seed=3)
    rho = [x.value("rho") for x in a]
    assert a == b and len(set(rho)) == 8 and all(0.1 <= r <= 0.9 for r in rho)
    c = sweep.build_settings(["imocs"], [P("rho", None, lo=0.1, hi=0.9)], pops=(8,), iters=(3,), design="random",
                             samples=8, seed=4)
    assert [x.value("rho") for x in c] != rho


def test_best_known_reference_is_computed_once_per_problem_and_recorded(tmp_path, monkeypatch):
    """The default reference: the best-known front, cached on disk by the problem's identity
    (tiny settings here), recorded in the folder; a second study of the same problem reuses it."""
    from dockjax import config

    monkeypatch.setattr(config, "BEST_KNOWN", dict(n_points=4, n_exact=2, steps=5))
    monkeypatch.setenv("DOCKJAX_FRONTS", str(tmp_path / "fronts"))
    args = [a for a in TINY if a not in ("--reference", "pilot")]
    assert _main([*args, "--out", str(tmp_path / "a")]) == 0
    cached = list((tmp_path / "fronts").glob("best-known-*.npz"))
    assert len(cached) == 1
    mtime = cached[0].stat().st_mtime_ns
    cfg = sweep.load_config(tmp_path / "a")
    assert cfg.reference["kind"] == "best-known"
    ref = np.load(tmp_path / "a" / "reference.npz")
    assert str(ref["source"]) == "best-known" and len(ref["front"]) >= 2
    assert _main([*S.argv(args, "--seeds", "1"), "--out", str(tmp_path / "b")]) == 0
    assert cached[0].stat().st_mtime_ns == mtime  # reused, not recomputed
    np.testing.assert_array_equal(np.load(tmp_path / "b" / "reference.npz")["front"], ref["front"])


def test_reference_front_file(tmp_path):
    path = tmp_path / "front.csv"
    path.write_text("T,jerk\n40,1\n35,2\n36,3\n30,5\n")
    F = sweep.load_front_file(path)
    np.testing.assert_array_equal(F, [[30, 5], [35, 2], [40, 1]])  # (36, 3) is dominated
    cfg, front = sweep.make_config(reference_front=path)
    assert cfg.reference["kind"] == "file" and cfg.reference["points"] == 3
    np.testing.assert_array_equal(front, F)
    bad = tmp_path / "bad.csv"
    bad.write_text("1,2,3\n")
    with pytest.raises(sweep.ConfigError, match="reference-front"):
        sweep.make_config(reference_front=bad)


def test_memetic_option_is_part_of_the_configuration():
    plain, memetic = _cfg(), _cfg(refine_steps=50)
    assert plain.identity() != memetic.identity()
    plan = sweep.plan_round(memetic, 0, np.ones(4, bool), range(2))
    assert all(c.refine_steps == 50 and c.label == "imocs+refine" for c in plan)
    assert sweep.pilot_spec(memetic).refine_steps == 50
    assert sweep.plan_round(plain, 0, np.ones(4, bool), range(2))[0].label == "imocs"
    assert math.isnan(plain.settings[0].value("w"))
