"""Every benchmark script runs: each ``benchmarks/bench_*.py`` documents, in its module
docstring, one command line ending in ``# quick`` (tiny sizes, at the shapes the other tests
compile, so the persistent compilation cache serves both), and its ``main(argv)`` is called
here with that command line's options, in this process.

The scripts run in a temporary working folder, with :mod:`tempfile`'s folder inside it, so
whatever they write lands there rather than in the repository; the JAX settings a script
changes (the compilation cache, as a command line does) are restored afterwards. A peer
that is not installed is the script's business: it prints that it skipped it; with every
optional peer installed, nothing may be skipped.
"""

from __future__ import annotations

import ast
import importlib.util
import shlex
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted((ROOT / "benchmarks").glob("bench_*.py"))
MARK = "# quick"
PEERS = ("pymoo", "ruckig", "toppra")
"""Optional packages some scripts compare against (the ``bench`` extra)."""


def _quick_lines(path: Path) -> list[str]:
    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    return [line.strip() for line in doc.splitlines() if line.rstrip().endswith(MARK)]


def _quick_argv(path: Path) -> list[str]:
    """The options of the script's quick command line."""
    (line,) = _quick_lines(path)
    words = shlex.split(line[: -len(MARK)])
    assert words[:2] == ["python", f"benchmarks/{path.name}"], line
    return words[2:]


def _load(path: Path):
    spec = importlib.util.spec_from_file_location(f"benchmarks_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _installed(name: str) -> bool:
    return importlib.util.find_spec(name) is not None


def test_the_benchmarks_are_found():
    assert len(SCRIPTS) >= 8


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: p.stem)
def test_each_script_has_one_quick_form_and_main_of_argv(path):
    assert len(_quick_lines(path)) == 1, f"{path.name}: one docstring line ending in {MARK!r}"
    _quick_argv(path)
    tree = ast.parse(path.read_text())
    main = next((n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "main"), None)
    assert main is not None, f"{path.name} has no main()"
    assert [a.arg for a in main.args.args] == ["argv"] and len(main.args.defaults) == 1, \
        f"{path.name}: main(argv: list[str] | None = None)"
    guard = [n for n in tree.body if isinstance(n, ast.If) and "__main__" in ast.unparse(n.test)]
    assert len(guard) == 1 and ast.unparse(guard[0].body[0]) == "main()", \
        f"{path.name}: if __name__ == '__main__': main()"


@pytest.fixture
def isolated(tmp_path, monkeypatch):
    """A temporary working folder that is also :mod:`tempfile`'s, and JAX's compilation
    cache settings restored after the test."""
    import jax

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    names = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs")
    saved = {name: getattr(jax.config, name) for name in names}
    yield tmp_path
    for name, value in saved.items():
        jax.config.update(name, value)


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: p.stem)
def test_quick_form_runs_in_process(path, isolated, capsys):
    argv = _quick_argv(path)
    _load(path).main(argv)
    out = capsys.readouterr().out
    assert out.strip(), f"{path.name} {shlex.join(argv)} printed nothing"
    if all(_installed(name) for name in PEERS):
        assert "skipped" not in out, f"{path.name} {shlex.join(argv)} skipped a peer that is installed:\n{out}"
