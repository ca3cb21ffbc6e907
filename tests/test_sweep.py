"""Resumable hyper-parameter sweeps (dockjax.sweep, ``dockjax sweep``, experiments/sweep.py).

Tiny settings throughout (pop 8, 3 iterations, 2 × 2 grid, 2 seeds, chunks of 2 → 4 chunks).
The end-to-end runs are subprocesses of the real CLI; they share JAX's persistent
compilation cache, so only the first one compiles.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dockjax import cli, sweep
from dockjax.sweep.config import PILOT_SEED0

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "experiments" / "sweep.py"
TINY = ["--pop", "8", "--iters", "3", "--rho", "0.3", "0.5", "--alpha-max", "0.1", "0.2",
        "--seeds", "2", "--chunk", "2", "--no-progress"]
FIGURES = ("heatmap_hv_pop8.png", "hv_vs_pop.png", "fronts_best_worst.png")


def _main(argv: list[str]) -> int:
    return cli.main(["sweep", *argv])


def _env(**extra) -> dict:
    env = dict(os.environ)
    env.pop("DOCKJAX_SWEEP_PAUSE", None)
    env.update(extra)
    return env


def _cli(out: Path, *extra: str, **popen) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *TINY, "--out", str(out), *extra], cwd=ROOT,
                          env=_env(), capture_output=True, text=True, timeout=300, **popen)


def _table(out: Path) -> list[list[str]]:
    """runs.csv without the wall_s column."""
    lines = (out / "runs.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header[-1] == "wall_s"
    return [line.split(",")[:-1] for line in lines]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    out = tmp_path_factory.mktemp("sweep") / "full"
    proc = _cli(out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out, proc


def test_end_to_end_writes_table_and_figures(uninterrupted):
    out, proc = uninterrupted
    rows = _table(out)
    assert rows[0] == list(sweep.COLUMNS[:-1])
    assert len(rows) == 1 + 8
    body = [dict(zip(rows[0], r)) for r in rows[1:]]
    keys = [(float(r["rho"]), float(r["alpha_max"]), int(r["seed"])) for r in body]
    assert keys == sorted(keys) and len(set(keys)) == 8  # sorted, every run once
    assert all(r["algorithm"] == "imocs" and r["pop"] == "8" and r["iterations"] == "3" for r in body)
    hv = np.array([float(r["HV"]) for r in body])
    assert np.all(np.isfinite(hv)) and np.all(hv >= 0)
    assert sorted(p.name for p in (out / "chunks").iterdir()) == [f"chunk-{i:05d}.npz" for i in range(4)]
    for name in ("config.json", "reference.npz", "summary.csv", "summary.md", "fronts.npz", *FIGURES):
        assert (out / name).stat().st_size > 0, name
    assert not [p for p in out.rglob(".*")], "temporary files left behind"
    fronts = np.load(out / "fronts.npz")
    assert fronts["offsets"][-1] == len(fronts["F"]) and len(fronts["run_id"]) == 8
    assert "best by median HV" in proc.stdout and "IQR" in proc.stdout


def test_kill_and_resume_gives_the_same_table(uninterrupted, tmp_path):
    full, _ = uninterrupted
    out = tmp_path / "killed"
    # the pause after each chunk gives a window to kill the sweep between chunks
    proc = subprocess.Popen([sys.executable, str(SCRIPT), *TINY, "--out", str(out)], cwd=ROOT,
                            env=_env(DOCKJAX_SWEEP_PAUSE="60"), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 240
        while not list((out / "chunks").glob("chunk-*.npz")):
            assert proc.poll() is None, "sweep ended before writing a chunk"
            assert time.monotonic() < deadline, "no chunk file written in time"
            time.sleep(0.1)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    before = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (out / "chunks").glob("chunk-*.npz")}
    assert 1 <= len(before) < 4
    assert not (out / "runs.csv").exists()

    resumed = _cli(out)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert f"resuming: {len(before)} of 4 chunks already done" in resumed.stdout
    after = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (out / "chunks").glob("chunk-*.npz")}
    assert len(after) == 4
    assert {k: after[k] for k in before} == before  # chunks finished before the kill were not rewritten
    assert _table(out) == _table(full)


def test_dask_backend_gives_the_same_table(uninterrupted, tmp_path):
    pytest.importorskip("distributed")
    full, _ = uninterrupted
    out = tmp_path / "dask"
    proc = _cli(out, "--backend", "dask", "--workers", "2")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert _table(out) == _table(full)
    assert sorted(p.name for p in (out / "chunks").iterdir()) == [f"chunk-{i:05d}.npz" for i in range(4)]


def test_a_folder_with_another_configuration_is_refused(uninterrupted, capsys):
    out, _ = uninterrupted
    listing = {p: p.stat().st_mtime_ns for p in out.rglob("*")}
    code = _main([*TINY, "--rho", "0.3", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert "different sweep configuration" in err and "rho" in err and len(err.strip().splitlines()) == 1
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*")} == listing
    assert _main([*TINY, "--chunk", "3", "--out", str(out)]) == 2
    assert "chunk" in capsys.readouterr().err


@pytest.mark.parametrize("extra, message", [
    (["--rho", "0.3", "1.5"], "--rho values must be in (0, 1)"),
    (["--rho", "0"], "--rho values must be in (0, 1)"),
    (["--alpha-max", "0"], "--alpha-max values must be > 0"),
    (["--alpha-max", "-0.1", "0.1"], "--alpha-max values must be > 0"),
    (["--pop", "3"], "--pop values must be >= 4"),
    (["--rho"], "--rho grid is empty"),
    (["--pop"], "--pop grid is empty"),
    (["--seeds", "0"], "--seeds must be >= 1"),
    (["--refine-steps", "-1"], "--refine-steps must be >= 0"),
    (["--scheduler", "tcp://localhost:1"], "--scheduler needs --backend dask"),
    (["--devices", "0"], "--devices must be an integer >= 1"),
])
def test_bad_input_exits_2_before_compiling_and_leaves_no_folder(tmp_path, capsys, extra, message):
    out = tmp_path / "new" / "sweep"
    code = _main([*TINY, *extra, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.startswith("error: ") and len(err.strip().splitlines()) == 1
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


def test_cli_exit_code_2_in_a_subprocess(tmp_path):
    out = tmp_path / "x"
    proc = _cli(out, "--rho", "1.2")
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == ["error: --rho values must be in (0, 1), got [1.2]"]
    assert not out.exists()


def _cfg(**kw) -> sweep.SweepConfig:
    base = dict(algorithm="imocs", preset="paper", pop=(8,), rho=(0.3, 0.5), alpha_max=(0.1, 0.2), seeds=2,
                iters=3, chunk=2, reference={"kind": "pilot"})
    return sweep.SweepConfig(**{**base, **kw})


def test_plan_is_balanced_padded_and_deterministic():
    cfg = _cfg(pop=(8, 12), rho=(0.3, 0.4, 0.5), alpha_max=(0.05, 0.1, 0.2), chunk=16)
    plan = sweep.plan_chunks(cfg)
    assert [(c.pop, len(c.seeds), c.n_real) for c in plan] == [(8, 9, 9), (8, 9, 9), (12, 9, 9), (12, 9, 9)]
    assert sorted(i for c in plan for i in c.run_ids) == list(range(36))
    assert plan == sweep.plan_chunks(cfg)
    odd = sweep.plan_chunks(_cfg(rho=(0.3,), alpha_max=(0.1, 0.2, 0.3), seeds=1, chunk=2))
    assert [(len(c.seeds), c.n_real) for c in odd] == [(2, 2), (2, 1)]
    assert odd[-1].seeds == (0, 0) and odd[-1].alpha_max == (0.3, 0.3)  # padded with its own run
    pilot = sweep.pilot_spec(cfg)
    assert len(pilot.seeds) == 9 and pilot.pop == 12 and min(pilot.seeds) >= PILOT_SEED0


def test_other_algorithms_collapse_the_grid():
    cfg = _cfg(algorithm="nsga2", rho=None, alpha_max=None, pop=(8, 12), seeds=3, chunk=16)
    plan = sweep.plan_chunks(cfg)
    assert cfg.n_runs() == 6 and len(plan) == 2
    assert all(math.isnan(r) for c in plan for r in c.rho)
    made, _ = sweep.make_config(algorithm="mopso", rho=(0.3, 0.4), alpha_max=(0.1,), pop=(8,))
    assert made.rho is None and made.alpha_max is None and len(made.settings()) == 1


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
    # a folder written without the option keeps its identity (still resumable) ...
    assert "refine_steps" not in plain.identity() and memetic.identity()["refine_steps"] == 50
    assert plain.identity() != memetic.identity()  # ... and refuses to mix with a memetic sweep
    plan = sweep.plan_chunks(memetic)
    assert all(c.refine_steps == 50 and c.label == "imocs+refine" for c in plan)
    assert sweep.pilot_spec(memetic).refine_steps == 50
    assert sweep.plan_chunks(plain)[0].label == "imocs"
