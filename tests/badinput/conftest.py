"""Fixtures of the bad-input corpus: the bad files, made once per session in a temp folder.

Lengths in the files are mm (see :mod:`badinput._files`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from badinput._files import make_bad_files


def sha256_of(path: Path) -> str | None:
    """SHA-256 of a file (None for folders and missing paths)."""
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


@pytest.fixture(scope="session")
def bad_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``{name: path}`` of the corpus files (read-only for the tests: their hashes are checked)."""
    return make_bad_files(tmp_path_factory.mktemp("bad-input"))
