"""Nothing lost, nothing mixed, nothing unbounded: races resume from any point, one writer per
folder, chunk files that prove what they are, bounded requests, strict input files, and
every input used or refused. In-process where a process is not the point; real processes
for the folder lock."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from dockjax import cli, sweep
from dockjax.io import LOCK_NAME, load_npz
from tests import sweeps as S

ROOT = Path(__file__).resolve().parents[1]


def _cli(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(argv)
    return code, out.getvalue(), err.getvalue()


def _interrupted(out: Path, base, after: int) -> tuple[int, str]:
    """The sweep in this process, interrupted by a real SIGINT right after its ``after``-th
    chunk is written (as Ctrl-C, or ``kill -9``, would leave the folder)."""
    os.environ["DOCKJAX_SWEEP_SIGNAL"] = f"SIGINT:{after}"
    try:
        return _cli(["sweep", *base, "--out", str(out)])[::2]
    finally:
        del os.environ["DOCKJAX_SWEEP_SIGNAL"]


# -- races resume from any point -------------------------------------------------------


@pytest.mark.parametrize("after", [2, 4, 5, 7])
def test_a_race_interrupted_after_any_chunk_resumes_to_the_uninterrupted_table(tiny_race, tmp_path, after):
    """Interrupted in round 0 (after 2 of its 4 chunks), at its end (4), in round 1 (5) and
    in round 2 (7), then run again: the same decisions, the same runs.csv."""
    full, _ = tiny_race
    out = tmp_path / "race"
    code, err = _interrupted(out, S.RACE, after)
    assert code == 130 and "Traceback" not in err
    assert len(list((out / "chunks").glob("round-*.npz"))) == after
    assert S.run(out, S.RACE)[0] == 0
    assert S.table(out) == S.table(full)
    assert (out / "summary.csv").read_text() == (full / "summary.csv").read_text()


def test_a_dask_race_interrupted_in_round_1_resumes_to_the_uninterrupted_table(tiny_race, tmp_path):
    """The same with the Dask backend (two workers): interrupted in round 1, then resumed,
    it ends with the local uninterrupted race's runs.csv."""
    pytest.importorskip("distributed")
    full, _ = tiny_race
    out = tmp_path / "race"
    dask = [*S.RACE, "--backend", "dask", "--workers", "2"]
    code, err = _interrupted(out, dask, 5)
    assert code == 130 and "Traceback" not in err
    assert len(list((out / "chunks").glob("round-*.npz"))) == 5
    assert S.run(out, dask)[0] == 0
    assert S.table(out) == S.table(full)


def test_a_finished_race_run_again_recomputes_nothing_and_decides_the_same(tiny_race, tmp_path):
    full, _ = tiny_race
    out = tmp_path / "again"
    shutil.copytree(full, out)
    mtimes = {p.name: p.stat().st_mtime_ns for p in (out / "chunks").iterdir()}
    code, stdout = S.run(out, S.RACE)
    assert code == 0 and "computed again" not in stdout
    assert {p.name: p.stat().st_mtime_ns for p in (out / "chunks").iterdir()} == mtimes
    assert S.table(out) == S.table(full)


# -- every chunk proves what it is ------------------------------------------------------


def _strip_checksum(path: Path, change: bool) -> None:
    z = dict(np.load(path, allow_pickle=False))
    z.pop("__sha256__")
    if change:
        z["HV"] = z["HV"] + 0.25
    with open(path, "wb") as fh:
        np.savez(fh, **z)


def test_chunks_that_are_not_this_places_result_are_recomputed(tiny_sweep, tmp_path):
    """A chunk of another study with the right name, a chunk moved to another place, one
    whose checksum was removed and data changed, and a stray extra chunk: each is named and
    recomputed (or left out), never read as a result; runs.csv is the true one."""
    full, _ = tiny_sweep
    other = tmp_path / "other"
    assert S.run(other, S.TINY, "--rho", "0.35", "0.5")[0] == 0  # another study, the same file names
    out = tmp_path / "s"
    shutil.copytree(full, out)
    chunks = out / "chunks"
    shutil.copy(other / "chunks" / "round-000-chunk-00000.npz", chunks / "round-000-chunk-00000.npz")
    shutil.copy(chunks / "round-000-chunk-00002.npz", chunks / "round-000-chunk-00001.npz")  # another place's
    _strip_checksum(chunks / "round-000-chunk-00003.npz", change=True)
    shutil.copy(chunks / "round-000-chunk-00002.npz", chunks / "round-000-chunk-00099.npz")  # stray
    code, stdout = S.run(out)
    assert code == 0, stdout
    assert "round-000-chunk-00000.npz belongs to another study: computed again" in stdout
    assert "round-000-chunk-00001.npz holds round [0] chunk [2], not this place's: computed again" in stdout
    assert "round-000-chunk-00003.npz damaged" in stdout and "no checksum" in stdout
    assert S.table(out) == S.table(full)
    assert len((out / "runs.csv").read_text().splitlines()) == 1 + 8  # the stray file is not merged


def test_a_config_whose_identity_is_damaged_is_refused_with_exit_2(tiny_sweep, tmp_path):
    full, _ = tiny_sweep
    out = tmp_path / "s"
    shutil.copytree(full, out)
    (out / "config.json").write_text(json.dumps({"identity": "not a mapping"}))
    code, _, err = _cli(["sweep", *S.TINY, "--out", str(out)])
    assert code == 2 and "config.json" in err and "Traceback" not in err and "internal" not in err


# -- one writer per folder ----------------------------------------------------------------


HOLD = r"""
import importlib.util, sys, time
spec = importlib.util.spec_from_file_location("dockjax_io", sys.argv[1])
io = importlib.util.module_from_spec(spec); spec.loader.exec_module(io)
folder, me, hold = sys.argv[2], sys.argv[3], float(sys.argv[4])
try:
    lock = io.FolderLock(folder, f"writer {me}").acquire()
except io.FolderBusyError as exc:
    print(exc); sys.exit(2)
open(f"{folder}/marker", "w").write(me)
time.sleep(hold)
sys.exit(0 if open(f"{folder}/marker").read() == me else 3)  # 3: another writer wrote meanwhile
"""


def test_two_processes_never_write_one_folder_at_once(tmp_path):
    """Twenty pairs of real processes take one folder with random delays: whenever they
    overlap, one is refused naming the other's PID and command, and no writer ever sees
    the other's write in the middle of its own."""
    rng = random.Random(0)
    folder = tmp_path / "f"
    folder.mkdir()
    refused = 0
    for _ in range(20):
        procs = []
        for me in "AB":
            procs.append(subprocess.Popen([sys.executable, "-c", HOLD, str(ROOT / "dockjax" / "io.py"), str(folder),
                                           me, str(rng.uniform(0.05, 0.3))], stdout=subprocess.PIPE, text=True))
            time.sleep(rng.uniform(0.0, 0.15))
        results = [(p.wait(timeout=60), p.stdout.read()) for p in procs]
        assert all(code in (0, 2) for code, _ in results), results  # never 3
        for code, text in results:
            if code == 2:
                refused += 1
                assert "is in use by PID" in text and "writer" in text
    assert refused >= 5  # the delays do make them overlap


def test_a_refusal_names_a_holder_that_has_not_yet_written_its_name(tmp_path):
    """A holder writes its PID and command just after taking the lock: a process refused in
    between waits for the name rather than saying "another process"."""
    import fcntl
    import threading

    from dockjax.io import FolderBusyError, FolderLock

    fd = os.open(tmp_path / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # held, the file still empty
    late = threading.Timer(0.2, lambda: os.write(fd, b"PID 12345 (writer late)"))
    late.start()
    try:
        with pytest.raises(FolderBusyError, match=r"is in use by PID 12345 \(writer late\)"):
            FolderLock(tmp_path, "writer early").acquire()
    finally:
        late.join()
        os.close(fd)


def test_a_second_sweep_on_a_busy_folder_exits_2_naming_the_holder(tmp_path):
    """A real second ``dockjax sweep`` on a folder that another process holds; after the
    holder ends — killed, here — the folder is free again."""
    out = tmp_path / "s"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(ROOT / "dockjax" / "io.py"), str(out), "X", "600"],
                              stdout=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not (out / "marker").exists():
            assert time.monotonic() < deadline
            time.sleep(0.02)
        code, _, err = _cli(["sweep", *S.TINY, "--out", str(out)])
        assert code == 2 and f"is in use by PID {holder.pid} (writer X)" in err
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME, "marker"]  # nothing of the sweep written
    finally:
        holder.send_signal(signal.SIGKILL)
        holder.wait()
    (out / "marker").unlink()
    assert sweep.claim_folder(out, sweep.make_config(pop=(8,), iters=(3,), reference="pilot")[0]).release() is None


# -- bounded requests, strict input files ------------------------------------------------------


@pytest.mark.parametrize("argv, needle", [
    (["sweep", "--design", "sobol", "--samples", "10000000", "--param", "p_a=0:1"], "settings"),
    (["sweep", "--design", "random", "--samples", "1000000", "--param", "p_a=0:1"], "settings"),
    (["sweep", "--iters", "1000000000"], "evaluations"),
    (["sweep", "--budget", "1000000000000000000"], "--budget"),
    (["sweep", "--iters", "9223372036854775808"], "--iters"),
    (["sweep", "--budget", "1e30"], "--budget"),
    (["sweep", "--workers", "1000"], "--workers"),
    (["compare", "--iters", "1000000000"], "evaluations"),
    (["compare", "--best-known-points", "100000000"], "--best-known-points"),
    (["plan", "--n-front", "100000"], "--n-front"),
    (["plan", "--rate", "10000", "--interval-bounds", "1", "1000000"], "--rate"),
])
def test_every_size_is_bounded_before_any_work(tmp_path, argv, needle):
    t0 = time.perf_counter()
    code, _, err = _cli([*argv, "--out", str(tmp_path / "o")])
    assert code == 2 and needle in err and err.startswith("error: ") and len(err.strip().splitlines()) == 1, err
    assert time.perf_counter() - t0 < 5 and not (tmp_path / "o").exists()


@pytest.mark.parametrize("option", ["--reference-front", "--limits"])
def test_a_fifo_or_a_device_as_an_input_file_is_refused_at_once(tmp_path, option):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    command = ["sweep", *S.TINY] if option == "--reference-front" else ["plan"]
    for path in (fifo, Path("/dev/zero"), tmp_path):
        code, _, err = _cli([*command, option, str(path), "--out", str(tmp_path / "o")])
        assert code == 2 and ("not a regular file" in err), err


@pytest.mark.parametrize("write, needle", [
    (lambda p: np.savez(p, front=np.ones((3, 2), bool)), "real numbers"),
    (lambda p: np.savez(p, front=np.ones((3, 2)) + 1j), "real numbers"),
    (lambda p: p.with_suffix(".csv").write_text("T,jerk\n30,1e400\n40,1\n"), "finite"),
    (lambda p: p.with_suffix(".csv").write_text("30,5\n"), "at least two"),
    (lambda p: p.with_suffix(".csv").write_text("30,5\n30,5\n"), "at least two"),
    (lambda p: p.with_suffix(".csv").write_text("30,5,1\n40,1,1\n"), "two columns"),
])
def test_reference_front_files_must_be_real_finite_and_a_front(tmp_path, write, needle):
    path = tmp_path / "front.npz"
    write(path)
    path = path if path.exists() else path.with_suffix(".csv")
    with pytest.raises(sweep.ConfigError, match=needle):
        sweep.load_front_file(path)


def test_a_reference_front_with_dominated_points_is_reduced_with_a_message(tmp_path):
    path = tmp_path / "front.csv"
    path.write_text("\ufeffT,jerk\n40,1\n35,2\n36,3\n30,5\n")  # a byte-order mark, a header, one dominated point
    lines = []
    np.testing.assert_array_equal(sweep.load_front_file(path, log=lines.append), [[30, 5], [35, 2], [40, 1]])
    assert "1 of 4 points" in lines[0]


def test_a_limits_file_with_a_byte_order_mark_is_read():
    from dockjax.plan import load_limits

    path = ROOT / ".pytest-bom-limits.toml"
    try:
        path.write_text("\ufeffvelocity = [400, 25, 2.5, 6.8]\n", encoding="utf-8")
        assert load_limits(path) == {"velocity": [400, 25, 2.5, 6.8]}
    finally:
        path.unlink()


# -- every input used or refused ---------------------------------------------------------------


def test_param_names_an_algorithm_in_any_case_and_may_be_given_twice():
    cfg, _ = sweep.make_config(params=[sweep.parse_param("IMOCS.rho=0.3"), sweep.parse_param("p_a=0.2")],
                               pop=(8,), iters=(3,), reference="pilot")
    assert [s.params for s in cfg.settings] == [(("p_a", 0.2), ("rho", 0.3))]
    args = cli.parse(["sweep", "--param", "imocs.rho=0.3", "--param", "p_a=0.2,0.3"])
    assert args.param == ("imocs.rho=0.3", "p_a=0.2,0.3")


def test_a_plan_of_no_move_is_refused(tmp_path):
    pose = ["775", "-35", "-1315", "0.2", "-0.2", "190"]
    code, _, err = _cli(["plan", "--start", *pose, "--goal", *pose, "--out", str(tmp_path / "o")])
    assert code == 2 and "same pose" in err and not (tmp_path / "o").exists()


# -- Ctrl-C in every phase, sets replaced whole -------------------------------------------------


def test_an_interrupt_swallowed_during_the_report_still_exits_130(tiny_sweep, tmp_path, monkeypatch):
    """An interrupt that arrives while the report draws its figures and is swallowed on
    its way (the interpreter does so inside a garbage-collection callback) still ends the
    command with 130; the report written is whole."""
    from dockjax import plots

    full, _ = tiny_sweep
    out = tmp_path / "s"
    shutil.copytree(full, out)
    (out / "report.md").unlink()
    real = plots.plot_front_groups

    def swallowing(*a, **k):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
        except KeyboardInterrupt:
            pass  # as a garbage-collection callback would
        return real(*a, **k)

    monkeypatch.setattr(plots, "plot_front_groups", swallowing)
    code, _, err = _cli(["sweep", *S.TINY, "--out", str(out)])
    assert code == 130 and "Traceback" not in err
    assert (out / "report.md").exists() and S.table(out) == S.table(full)


def test_an_interrupt_during_the_report_leaves_the_previous_report_whole(tiny_sweep, tmp_path, monkeypatch):
    from dockjax import plots

    full, _ = tiny_sweep
    out = tmp_path / "s"
    shutil.copytree(full, out)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and p.name != LOCK_NAME}

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(plots, "plot_front_groups", interrupted)
    code, _, err = _cli(["sweep", *S.TINY, "--out", str(out)])
    assert code == 130
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and p.name != LOCK_NAME} == before
    assert not [p for p in out.rglob(".dockjax-*")], "staging left behind"


def test_a_killed_plans_staging_is_removed_by_the_next_plan_and_users_files_are_kept(imocs_plan, tmp_path):
    from dockjax.plan import write_plan

    out = tmp_path / "p"
    out.mkdir()
    (out / ".dockjax-stage-abc.tmp").mkdir()  # a writer killed while staging
    (out / ".dockjax-stage-abc.tmp" / "trajectory.csv").write_text("half")
    (out / "notes.txt").write_text("mine")
    write_plan(imocs_plan, out)
    assert not (out / ".dockjax-stage-abc.tmp").exists() and (out / "notes.txt").read_text() == "mine"
    assert zipfile.is_zipfile(out / "front.png") is False and (out / "front.png").stat().st_size > 0


def test_load_npz_requires_a_checksum_when_asked(tmp_path):
    from dockjax.io import DamagedFileError

    path = tmp_path / "a.npz"
    np.savez(path, x=np.arange(3))
    np.testing.assert_array_equal(load_npz(path)["x"], np.arange(3))
    with pytest.raises(DamagedFileError, match="no checksum"):
        load_npz(path, require_checksum=True)


def test_the_lock_module_loads_without_the_package():
    spec = importlib.util.spec_from_file_location("dockjax_io_alone", ROOT / "dockjax" / "io.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.LOCK_NAME == LOCK_NAME
