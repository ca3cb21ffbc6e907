"""The tiny studies the sweep tests share, and how they run them.

Tiny settings throughout (pop 8, 3 iterations, 2 × 2 grid of ρ × α_max, chunks of 2; the
reference a pilot, so no best-known front is computed): every study of the tests is the
same compiled program.
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
from pathlib import Path

from dockjax import cli

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "experiments" / "sweep.py"
TINY = ["--pop", "8", "--iters", "3", "--rho", "0.3", "0.5", "--alpha-max", "0.1", "0.2",
        "--seeds", "2", "--chunk", "2", "--no-progress", "--reference", "pilot"]
"""4 settings × 2 seeds in 4 chunks."""
RACE = ["--pop", "8", "--iters", "3", "--rho", "0.3", "0.5", "--alpha-max", "0.1", "0.2",
        "--seeds", "5", "--chunk", "2", "--no-progress", "--reference", "pilot", "--race", "--race-min-seeds", "2"]
"""The same 4 settings raced over 5 seeds: round 0 (2 seeds) in 4 chunks, then a seed a round."""


def argv(base: list[str], *extra: str) -> list[str]:
    """``base`` with ``extra`` in place of the options ``extra`` gives (an option may be
    given only once)."""
    given = {t.split("=")[0] for t in extra if t.startswith("--")}
    kept, skip = [], False
    for token in base:
        if token.startswith("--"):
            skip = token.split("=")[0] in given
        if not skip:
            kept.append(token)
    return [*kept, *extra]


def run(out: Path, base=TINY, *extra: str) -> tuple[int, str]:
    """``dockjax sweep BASE EXTRA --out OUT`` (``extra`` replacing options of ``base``) in this
    process: (exit code, what it printed)."""
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        code = cli.main(["sweep", *argv(base, *extra), "--out", str(out)])
    return code, text.getvalue()


def process(out: Path, base=TINY, signal_after: str | None = None, *extra: str) -> subprocess.CompletedProcess:
    """The sweep as a real process (one CPU device, as this one), optionally sending itself
    a signal after a chunk (``DOCKJAX_SWEEP_SIGNAL``); SIGINT as a terminal would deliver it,
    even when this test run started with SIGINT ignored."""
    env = {k: v for k, v in os.environ.items() if k != "DOCKJAX_SWEEP_SIGNAL"}
    if signal_after:
        env["DOCKJAX_SWEEP_SIGNAL"] = signal_after
    # Python leaves SIGINT ignored in a child started with it ignored (nohup, `&` in a script)
    shim = ("import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
            "sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0], run_name='__main__')")
    return subprocess.run([sys.executable, "-c", shim, str(SCRIPT), *base, "--devices", "1", "--out", str(out),
                           *extra], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)


def table(out: Path) -> list[list[str]]:
    """runs.csv without the wall_s column."""
    lines = (out / "runs.csv").read_text().splitlines()
    header = lines[0].split(",")
    assert header[-1] == "wall_s"
    return [line.split(",")[:-1] for line in lines]
