"""Static checks of the code base: ruff (lint and format) and mypy, as configured in pyproject.toml.

They run as part of the README's test command so a clean checkout is held to them; each
test prints the tool's own report when it fails.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CHECKED = ["workbench", "tests", "benchmarks", "examples"]


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", *args], cwd=REPO, capture_output=True, text=True, check=False
    )


def test_ruff_lint_is_clean() -> None:
    done = _run("ruff", "check", "--no-cache", *CHECKED)
    assert done.returncode == 0, done.stdout + done.stderr


def test_ruff_format_is_clean() -> None:
    done = _run("ruff", "format", "--check", "--no-cache", *CHECKED)
    assert done.returncode == 0, "run `ruff format workbench tests benchmarks`:\n" + done.stdout


@pytest.mark.timeout(900)
def test_mypy_is_clean(tmp_path: Path) -> None:
    done = _run("mypy", "--cache-dir", str(tmp_path / "mypy_cache"))
    assert done.returncode == 0, done.stdout + done.stderr
