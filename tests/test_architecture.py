"""Layer contracts (import-linter) and a headless import of every non-Qt package."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_import_linter_contracts_hold() -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from importlinter.cli import lint_imports_command; "
            "sys.argv=['lint-imports','--no-cache']; lint_imports_command()",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "broken" in done.stdout and "0 broken" in done.stdout


def test_non_gui_layers_import_without_qt_or_vtk() -> None:
    script = textwrap.dedent("""
        import importlib, pkgutil, sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in {'PySide6', 'pyvistaqt', 'qtpy', 'vtk', 'vtkmodules', 'pyvista'}:
                    raise ImportError('blocked for the headless test: ' + name)
        sys.meta_path.insert(0, Block())
        import workbench
        for layer in ('core', 'model', 'commands', 'io', 'services', 'reporting'):
            pkg = importlib.import_module('workbench.' + layer)
            for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):
                importlib.import_module(info.name)
        print('ok')
    """)
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, check=False
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def _cycles(graph) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for root in sorted(graph.modules):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.find_modules_directly_imported_by(root))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append(
                        (child, iter(sorted(graph.find_modules_directly_imported_by(child))))
                    )
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    comp.append(m)
                    if m == node:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_no_import_cycles() -> None:
    """No module of workbench imports itself back through others, counting imports made
    inside functions and those for annotations only (under TYPE_CHECKING)."""
    import grimp

    graph = grimp.build_graph("workbench", cache_dir=None)
    cycles = _cycles(graph)
    assert cycles == [], "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)
    # the helper itself finds a cycle when there is one
    fake = _FakeGraph({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}})
    assert _cycles(fake) == [["a", "b", "c"]]


class _FakeGraph:
    def __init__(self, edges: dict[str, set[str]]) -> None:
        self.edges = edges
        self.modules = set(edges)

    def find_modules_directly_imported_by(self, module: str) -> set[str]:
        return self.edges[module]


#: the size a newcomer can read in one go (issue 32): lines per module, per function
MAX_MODULE_LINES = 800
MAX_FUNCTION_LINES = 150


def _too_long(root: Path) -> tuple[list[str], list[str]]:
    """Modules over :data:`MAX_MODULE_LINES` lines and functions (def line to last line,
    docstring included) over :data:`MAX_FUNCTION_LINES` below ``root``."""
    import ast

    modules, functions = [], []
    for path in sorted(root.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        if text.count("\n") > MAX_MODULE_LINES:
            modules.append(f"{path.relative_to(root.parent)} ({text.count(chr(10))} lines)")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = (node.end_lineno or node.lineno) - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    functions.append(f"{path.relative_to(root.parent)}:{node.name} ({n} lines)")
    return modules, functions


def test_modules_and_functions_fit_on_a_few_screens(tmp_path: Path) -> None:
    modules, functions = _too_long(REPO / "workbench")
    assert modules == [], "modules over 800 lines: " + ", ".join(modules)
    assert functions == [], "functions over 150 lines: " + ", ".join(functions)
    # the check itself finds a long function and a long module
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    (pkg / "long.py").write_text(f"def f():\n{body}\n" + "\n" * MAX_MODULE_LINES, "utf-8")
    modules, functions = _too_long(pkg)
    assert len(modules) == 1 and functions == ["pkg/long.py:f (151 lines)"]
