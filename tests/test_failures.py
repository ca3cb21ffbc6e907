"""Every failure a user can cause gets a clear answer (exit codes 2 / 1 / 130, one line, no
traceback), damaged result files are recognised, and outputs are never half-written."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from dockjax import DockingProblem
from dockjax.io import DamagedFileError, atomic_savez, load_npz
from dockjax.plan import load_limits

ROOT = Path(__file__).resolve().parents[1]
DOCKJAX = Path(sys.executable).parent / "dockjax"
SWEEP = [sys.executable, str(ROOT / "experiments" / "sweep.py"), "--pop", "8", "--iters", "3", "--seeds", "1",
         "--rho", "0.3", "--alpha-max", "0.1", "--no-progress", "--reference", "pilot", "--devices", "1"]
ENV = {**os.environ, "DOCKJAX_CACHE": str(ROOT / ".pytest-jax-cache")}


def _run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, env=ENV, timeout=900, **kw)


def _flip_inside(path: Path, member: str) -> None:
    """Flip one byte inside the data of ``member`` of an uncompressed .npz."""
    with zipfile.ZipFile(path) as z:
        info = z.getinfo(member)
    raw = bytearray(path.read_bytes())
    # local header: 30 bytes + name + extra, then the data; flip a byte near its end
    name_len = int.from_bytes(raw[info.header_offset + 26:info.header_offset + 28], "little")
    extra_len = int.from_bytes(raw[info.header_offset + 28:info.header_offset + 30], "little")
    start = info.header_offset + 30 + name_len + extra_len
    raw[start + info.compress_size - 1] ^= 0xFF
    path.write_bytes(bytes(raw))


# -- damaged files -----------------------------------------------------------------------


def test_checksum_round_trip_and_a_flipped_byte_is_named(tmp_path):
    path = tmp_path / "a.npz"
    atomic_savez(path, {"HV": np.arange(5.0), "seed": np.arange(5)})
    np.testing.assert_array_equal(load_npz(path)["HV"], np.arange(5.0))
    _flip_inside(path, "HV.npy")
    with pytest.raises(DamagedFileError, match="a.npz"):
        load_npz(path)
    path.write_bytes(b"")
    with pytest.raises(DamagedFileError, match="a.npz"):
        load_npz(path)


def test_damaged_chunk_and_reference_are_recomputed_with_the_same_table(tmp_path):
    out = tmp_path / "s"
    r = _run([*SWEEP, "--out", str(out)])
    assert r.returncode == 0, r.stderr[-1500:]
    before = (out / "summary.csv").read_text()
    chunk = next((out / "chunks").glob("round-*-chunk-*.npz"))
    _flip_inside(chunk, "HV.npy")
    _flip_inside(out / "reference.npz", "front.npy")
    r = _run([*SWEEP, "--out", str(out)])
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr[-1500:]
    assert "damaged" in r.stdout + r.stderr
    assert (out / "summary.csv").read_text() == before
    load_npz(chunk)  # whole again


def test_stale_temporary_files_are_removed_on_resume(tmp_path):
    out = tmp_path / "s"
    assert _run([*SWEEP, "--out", str(out)]).returncode == 0
    stale = out / ".eaf.png.abc123.tmp"
    stale.write_bytes(b"half")
    assert _run([*SWEEP, "--out", str(out)]).returncode == 0
    assert not stale.exists()


# -- bad input through the installed scripts -----------------------------------------------


LONG = "x" * 300


@pytest.mark.parametrize("cmd, needle", [
    (["demo", "--n", "10000000000"], "--n"),
    (["demo", "--seed", "-1"], "--seed"),
    (["plan", "--seed", str(2**70)], "--seed"),
    (["plan", "--rate", "1e9"], "--rate"),
    (["sweep", "--seeds", "1000000000"], "--seeds"),
    (["sweep", "--pop", "100000000"], "--pop"),
    (["compare", "--seeds", "1000000000"], "--seeds"),
    (["track", "--bandwidth", "500"], "unstable"),
])
def test_bad_values_exit_2_with_one_line_and_write_nothing(tmp_path, cmd, needle):
    out = tmp_path / "out"
    r = _run([str(DOCKJAX), *cmd, "--out", str(out)] if cmd[0] != "demo" else [str(DOCKJAX), *cmd])
    assert r.returncode == 2, (r.returncode, r.stderr[-800:])
    assert needle in r.stderr and "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0
    assert not out.exists()


@pytest.mark.parametrize("command", ["plan", "sweep", "compare", "track"])
def test_an_out_name_over_the_file_systems_limit_exits_2(tmp_path, command):
    r = _run([str(DOCKJAX), command, "--out", str(tmp_path / LONG)])
    assert r.returncode == 2, (r.returncode, r.stderr[-800:])
    assert "Traceback" not in r.stderr and "error:" in r.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("text, suffix, needle", [
    ("[velocity]\nx = 1\n", ".toml", "velocity must be a list"),
    ('velocity = ["fast", 25, 2.5, 6.8]\n', ".toml", "velocity must be a list"),
    ("velocity = [400, 25, 2.5, 6.8]\n", ".txt", None),
    ("not a table", ".txt", "neither JSON nor TOML"),
])
def test_limits_files_are_read_by_content_and_bad_ones_named(tmp_path, text, suffix, needle):
    path = tmp_path / f"limits{suffix}"
    path.write_text(text)
    if needle is None:
        assert load_limits(path) == {"velocity": [400, 25, 2.5, 6.8]}
    else:
        with pytest.raises(ValueError, match=needle) as info:
            load_limits(path)
        assert str(path) in str(info.value)


def test_ctrl_c_in_plan_exits_130_without_a_traceback(tmp_path):
    p = subprocess.Popen([str(DOCKJAX), "plan", "--method", "imocs", "--pop", "64", "--iters", "3000",
                          "--devices", "1", "--out", str(tmp_path / "out")], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=ENV)
    time.sleep(8)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err[-800:]
    assert "Traceback" not in err and "interrupted" in err
    assert not (tmp_path / "out" / "trajectory.csv").exists()


# -- the API is strict -----------------------------------------------------------------------


@pytest.mark.parametrize("kwargs, needle", [
    ({"reduced": "no"}, "reduced"),
    ({"margin": 1e308}, "margin"),
    ({"velocity": [True] * 4}, "velocity"),
    ({"velocity": ["fast", 25, 2.5, 6.8]}, "velocity"),
    ({"start": [1 + 1j] * 6}, "start"),
])
def test_problem_refuses_ill_typed_or_unbounded_fields(kwargs, needle):
    with pytest.raises(ValueError, match=needle):
        DockingProblem(**kwargs)


def test_evaluate_handles_empty_and_refuses_overflowing_or_complex_rows():
    p = DockingProblem()
    F, G = p.evaluate(np.zeros((0, p.n_var)))
    assert F.shape == (0, 2) and G.shape == (0, 24)
    x = p.lower + 0.5 * (p.upper - p.lower)
    for h in (1e-300, 1e300):
        X = x.copy()
        X[:6] = h
        with pytest.raises(ValueError, match="numeric range"):
            p.evaluate(X[None])
    with pytest.raises(ValueError, match="real numbers"):
        p.evaluate(x[None].astype(complex))
    with pytest.raises(ValueError, match="real numbers"):
        p.evaluate([[True] * p.n_var])


def test_plan_summary_is_valid_json_after_a_failed_rewrite(tmp_path, monkeypatch):
    from dockjax import plots
    from dockjax.plan import plan, write_plan

    p = plan(weights=(1.0, 0.0), rate=50, check_sensitivities=False)
    write_plan(p, tmp_path)
    before = {f.name: f.read_bytes() for f in tmp_path.iterdir()}

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(plots, "plot_joints", boom)
    with pytest.raises(OSError):
        write_plan(p, tmp_path)
    after = {f.name: f.read_bytes() for f in tmp_path.iterdir()}
    assert after == before  # nothing replaced, no temporary folder left
    json.loads(after["summary.json"])


def test_a_sweep_folder_resumes_only_with_its_device_count(tmp_path):
    out = tmp_path / "s"
    assert _run([*SWEEP, "--out", str(out)]).returncode == 0
    two = [a if a != "1" or SWEEP[i - 1] != "--devices" else "2" for i, a in enumerate(SWEEP)]
    r = _run([*two, "--out", str(out)])
    assert r.returncode == 2 and "devices" in r.stderr and "Traceback" not in r.stderr, r.stderr[-800:]
