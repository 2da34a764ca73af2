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
