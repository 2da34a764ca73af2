"""Numba's compiled kernels are cached in the platform's cache folder, not in site-packages."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

CODE = "import workbench.core.mass_spring, numba; print(numba.config.CACHE_DIR)"


def _cache_dir(env: dict[str, str]) -> str:
    out = subprocess.run(
        [sys.executable, "-c", CODE], env=env, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    return out.stdout.strip().splitlines()[-1]


@pytest.mark.skipif(sys.platform != "linux", reason="XDG cache folder on Linux")
def test_kernels_cache_in_the_platform_cache_folder(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    assert _cache_dir(env) == str(tmp_path / "forensic-workbench" / "numba")


def test_a_cache_folder_the_user_set_wins(tmp_path: Path) -> None:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "mine"))
    assert _cache_dir(env) == str(tmp_path / "mine")
