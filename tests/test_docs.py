"""The documentation is true to the code: every ``dockjax.…`` name it cites exists, every
Python snippet of the README runs on its own, and every command-line option the docs show
is one the command accepts."""

from __future__ import annotations

import ast
import contextlib
import importlib
import io
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SOURCES = sorted((ROOT / "dockjax").rglob("*.py"))
NAME = re.compile(r"`~?(dockjax(?:\.[A-Za-z_]\w*)+)")


def _docstrings(path: Path) -> str:
    """Every docstring of a module (module, classes, functions) and every string constant
    that documents an attribute, as one text."""
    tree = ast.parse(path.read_text())
    parts = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            parts.append(node.value.value)
    return "\n".join(parts)


def _cited() -> list[tuple[str, str]]:
    out = []
    for path in DOCS:
        out += [(path.name, m) for m in NAME.findall(path.read_text())]
    for path in SOURCES:
        out += [(str(path.relative_to(ROOT)), m) for m in NAME.findall(_docstrings(path))]
    return sorted(set(out))


def _resolve(dotted: str):
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ModuleNotFoundError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(dotted)


def test_every_cited_dockjax_name_exists():
    cited = _cited()
    assert len(cited) > 50  # the docs do cite the code
    missing = []
    for where, name in cited:
        try:
            _resolve(name)
        except (AttributeError, ModuleNotFoundError) as exc:
            missing.append(f"{where}: {name} ({type(exc).__name__})")
    assert not missing, "\n".join(missing)


ROLE = re.compile(r":(?:func|class|mod|meth|data|attr|exc):`~?([A-Za-z_.][\w.]*)`")


def test_every_cross_reference_of_a_docstring_resolves():
    """Sphinx-style references (``:func:`name```) resolve as a reader would: a relative
    one (``.mod``) in the package, a plain one in the module, one of its classes, or
    ``dockjax``."""
    missing = []
    for path in SOURCES:
        parts = path.relative_to(ROOT).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        module = importlib.import_module(name)
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        classes = [v for v in vars(module).values() if isinstance(v, type)]
        for ref in ROLE.findall(_docstrings(path)):
            head, *rest = ref.split(".")
            try:
                if ref.startswith("."):
                    _resolve(package + ref)
                elif ref.startswith("dockjax."):
                    _resolve(ref)
                elif hasattr(module, head):
                    _resolve(f"{name}.{ref}")
                elif any(hasattr(c, head) for c in classes):
                    obj = next(getattr(c, head) for c in classes if hasattr(c, head))
                    for attr in rest:
                        obj = getattr(obj, attr)
                else:
                    _resolve(f"dockjax.{ref}")
            except (AttributeError, ModuleNotFoundError):
                missing.append(f"{path.relative_to(ROOT)}: {ref}")
    assert not missing, "\n".join(missing)


def _snippets() -> list[str]:
    return re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)


def test_the_readme_has_python_snippets():
    assert len(_snippets()) >= 3


@pytest.mark.parametrize("index", range(len(_snippets())))
def test_each_readme_snippet_runs_on_its_own(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # files a snippet writes land here
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(_snippets()[index], f"README.md snippet {index}", "exec"), {"__name__": "__main__"})


def _commands() -> list[tuple[str, list[str]]]:
    """Every ``dockjax ...`` command line in a bash block of the docs (continuations joined)."""
    out = []
    for path in DOCS:
        for block in re.findall(r"```bash\n(.*?)```", path.read_text(), flags=re.S):
            text = block.replace("\\\n", " ")
            for line in text.splitlines():
                line = line.split("  #")[0].strip()
                if line.startswith("dockjax ") or line.startswith("python experiments/"):
                    out.append((path.name, shlex.split(line)))
    return out


def test_every_documented_command_line_parses():
    """Every command line of the docs names options its command has, with values it
    accepts (parsed as the command would, without running it)."""
    from dockjax import cli

    commands = _commands()
    assert len(commands) >= 8
    scripts = {"experiments/sweep.py": "sweep", "experiments/compare.py": "compare", "experiments/demo.py": "demo"}
    for where, argv in commands:
        argv = [scripts[argv[1]], *argv[2:]] if argv[0] == "python" else argv[1:]
        with contextlib.redirect_stderr(io.StringIO()) as err:
            parsed = cli.parse(argv)
        assert not isinstance(parsed, int), f"{where}: dockjax {' '.join(argv)}: {err.getvalue().strip()}"
