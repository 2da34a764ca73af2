"""Shared fixtures of the benchmark-case tests: the repository root importable (the
``benchmarks`` package), and a temporary robustness-corpus folder holding headsq's truth."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))


@pytest.fixture(scope="module")
def corpus_root(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A temporary corpus folder with the headsq truth, anchor and labels (real CT)."""
    from benchmarks.corpus import truth
    from benchmarks.corpus.bases import BASES

    path = shared_data / BASES["headsq"].relpath
    if not path.is_file():
        pytest.fail(f"real test data not found: {path}", pytrace=False)
    root = tmp_path_factory.mktemp("corpus")
    truth.load_truth("headsq", root)
    return root
