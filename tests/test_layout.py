"""The package's shape: data flows one way, with no import cycles, no imports inside
functions that hide one, and no import-time side effects."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "dockjax"
LAZY_OK = {"cli"}
"""Modules whose functions may import parts of the library (a subcommand loads only what it runs)."""
OPTIONAL = {"distributed", "pymoo"}
"""Optional third-party extras, imported where they are used."""


def _module(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _resolve(module: str, is_package: bool, level: int, name: str | None) -> str:
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (level - 1)] if level > 1 else base
    return ".".join(base + ([name] if name else []))


def _graph():
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        modules[_module(path)] = (path, path.name == "__init__.py")
    edges: dict[str, set[str]] = {m: set() for m in modules}
    inner: list[tuple[str, int, str]] = []
    for mod, (path, is_pkg) in modules.items():
        tree = ast.parse(path.read_text())

        def targets(node):
            if isinstance(node, ast.ImportFrom) and node.level:
                base = _resolve(mod, is_pkg, node.level, node.module)
                out = []
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    out.append(full if full in modules else base)
                return out
            if isinstance(node, ast.Import):
                return [a.name for a in node.names if a.name.split(".")[0] == "dockjax"]
            return []

        for node in tree.body:
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                continue  # annotations only
            for sub in ast.walk(node) if not isinstance(node, (ast.FunctionDef, ast.ClassDef)) else ():
                edges[mod].update(t for t in targets(sub) if t in modules and t != mod)
        for fn in ast.walk(tree):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for sub in ast.walk(fn):
                    if isinstance(sub, (ast.Import, ast.ImportFrom)):
                        names = [a.name for a in sub.names] if isinstance(sub, ast.Import) else [sub.module or ""]
                        if isinstance(sub, ast.ImportFrom) and sub.level:
                            inner.append((mod, sub.lineno, ast.unparse(sub)))
                        elif any(n.split(".")[0] not in OPTIONAL | {"tomllib"} for n in names):
                            inner.append((mod, sub.lineno, ast.unparse(sub)))
    return edges, inner


def test_the_package_has_no_import_cycles():
    edges, _ = _graph()
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(m):
        state[m] = 1
        path.append(m)
        for n in sorted(edges[m]):
            if state.get(n) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path[path.index(n):] + [n]))
            if n not in state:
                visit(n)
        path.pop()
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m)


def test_no_function_imports_the_library_outside_the_command_line():
    _, inner = _graph()
    bad = [(m, line, stmt) for m, line, stmt in inner if m.split(".")[-1] not in LAZY_OK]
    assert not bad, f"imports inside functions: {bad}"


def test_indicators_and_plots_load_no_optimiser_and_no_backend():
    # the raw rcParams value (get_backend() would itself load pyplot to resolve it)
    code = ("import sys, matplotlib; raw = lambda: dict.__getitem__(matplotlib.rcParams, 'backend'); "
            "before = raw(); import dockjax.metrics, dockjax.plots; "
            "assert not any(m.startswith('dockjax.algorithms') or m == 'dockjax.optimize' for m in sys.modules), "
            "[m for m in sys.modules if m.startswith('dockjax')]; "
            "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot'; assert raw() == before, 'backend'")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]


def test_data_flows_one_way():
    """The kernel never reaches the optimisers, the studies or the files; the optimisers
    never reach the studies or the command line."""
    edges, _ = _graph()

    def reach(m, seen=None):
        seen = set() if seen is None else seen
        for n in edges[m]:
            if n not in seen:
                seen.add(n)
                reach(n, seen)
        return seen

    kernel = ["dockjax.problem", "dockjax.limits", "dockjax.right_arm", "dockjax.objectives", "dockjax.decoding"]
    for m in kernel:
        r = reach(m)
        assert not {x for x in r if x.startswith(("dockjax.algorithms", "dockjax.optimize", "dockjax.sweep",
                                                   "dockjax.comparison", "dockjax.cli", "dockjax.plan"))}, (m, r)
    for m in ("dockjax.optimize", "dockjax.algorithms"):
        r = reach(m)
        assert not {x for x in r if x.startswith(("dockjax.sweep", "dockjax.comparison", "dockjax.cli",
                                                   "dockjax.plan"))}, (m, r)
    assert not {x for x in reach("dockjax.metrics") if x.startswith(("dockjax.algorithms", "dockjax.optimize"))}
    assert "dockjax.cli" not in reach("dockjax.sweep")


def test_the_robot_geometry_lives_in_one_module():
    """Which joints form an arm, which depend on the attitude and where the attitude sits in a
    pose are named once, in ``dockjax/robot.py`` (``LEFT_ARM``, ``RIGHT_ARM``,
    ``ATTITUDE_JOINTS``, ``POSE_ATTITUDE``), beside the one pose → joints map: no other module
    writes a range of more than one index with both ends constant (``x[4:7]``,
    ``slice(0, 4)``; a prefix such as the pose's position ``pose[..., :3]`` is not a joint
    group), and the kernel takes the map from the robot, not from the kinematics module."""
    edges, _ = _graph()
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "robot.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Slice) and all(isinstance(b, ast.Constant) for b in (node.lower, node.upper)):
                if node.upper.value - node.lower.value > 1:
                    found.append(f"{path.name}:{node.lineno} [{node.lower.value}:{node.upper.value}]")
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "slice" and node.args and all(
                    isinstance(a, ast.Constant) for a in node.args):
                found.append(f"{path.name}:{node.lineno} {ast.unparse(node)}")
    assert not found, found
    for m in ("limits", "right_arm", "objectives", "decoding", "trajectory"):
        assert "dockjax.kinematics" not in edges[f"dockjax.{m}"], m
        assert "dockjax.robot" in edges[f"dockjax.{m}"], m


def test_every_module_of_the_package_is_reachable_from_its_namespace():
    import dockjax

    modules = {p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__"}
    modules |= {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    assert modules == set(dockjax.MODULES)
