"""Every failure a user can cause gets a clear answer (exit codes 2 / 1 / 130, one line, no
traceback), damaged result files are recognised, and outputs are never half-written."""

from __future__ import annotations

import contextlib
import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from dockjax import DockingProblem, cli
from dockjax.io import DamagedFileError, atomic_savez, load_npz
from dockjax.plan import load_limits

SWEEP = ["sweep", "--pop", "8", "--iters", "3", "--seeds", "2", "--rho", "0.3", "--alpha-max", "0.1", "--no-progress",
         "--reference", "pilot"]  # the compiled shapes of tests/test_sweep.py


def _run(argv: list[str]) -> tuple[int, str, str]:
    """``dockjax ARGV`` in this process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(argv)
    return code, out.getvalue(), err.getvalue()


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
    code, _, err = _run([*SWEEP, "--out", str(out)])
    assert code == 0, err[-1500:]
    before = (out / "summary.csv").read_text()
    chunk = next((out / "chunks").glob("round-*-chunk-*.npz"))
    _flip_inside(chunk, "HV.npy")
    _flip_inside(out / "reference.npz", "front.npy")
    stale = out / ".dockjax-eaf.png.abc123.tmp"  # a temporary file of a write that was killed
    stale.write_bytes(b"half")
    mine = out / ".notes.abc.tmp"  # a user's own hidden file
    mine.write_text("keep me")
    code, stdout, err = _run([*SWEEP, "--out", str(out)])
    assert code == 0 and "Traceback" not in err, err[-1500:]
    assert "damaged" in stdout + err
    assert (out / "summary.csv").read_text() == before
    load_npz(chunk)  # whole again
    assert not stale.exists() and mine.read_text() == "keep me"


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
    (["plan", "--rate", "abc"], "--rate"),
    (["sweep", "--pop", "x"], "--pop"),
    (["plan", "--sellect", "time"], "--select"),
])
def test_bad_values_exit_2_with_one_line_and_write_nothing(tmp_path, cmd, needle):
    out = tmp_path / "out"
    code, _, err = _run([*cmd, "--out", str(out)] if cmd[0] != "demo" else cmd)
    assert code == 2, (code, err[-800:])
    assert needle in err and "Traceback" not in err and "[bold]" not in err
    assert err.strip().count("\n") == 0 and err.startswith("error: ")
    assert not out.exists()


@pytest.mark.parametrize("command", ["plan", "sweep", "compare", "track"])
def test_an_out_name_over_the_file_systems_limit_exits_2(tmp_path, command):
    code, _, err = _run([command, "--out", str(tmp_path / LONG)])
    assert code == 2, (code, err[-800:])
    assert "Traceback" not in err and "error:" in err
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


def test_plan_summary_is_valid_json_after_a_failed_rewrite(imocs_plan, tmp_path, monkeypatch):
    from dockjax import plots
    from dockjax.plan import write_plan

    p = imocs_plan
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
