"""Sample registry: every entry is real, hashed, and resolvable offline from the mirror."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from workbench.core.errors import WorkbenchError
from workbench.io import samples


def test_registry_entries_match_the_shared_data(shared_data: Path) -> None:
    reg = samples.registry()
    assert {"headsq", "skull"} <= set(reg)
    assert len(reg["headsq"].files) == 94  # header + 93 slices
    for sample in reg.values():
        assert sample.licence and sample.description
        assert sample.main in {f.path for f in sample.files}
        for f in sample.files:
            assert f.url.startswith("https://") and len(f.sha256) == 64
            local = shared_data / f.mirror
            assert hashlib.sha256(local.read_bytes()).hexdigest() == f.sha256, f.path


def test_fetch_seeds_the_cache_from_the_mirror(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path / "cache"))
    path = samples.fetch("headsq")
    assert path == tmp_path / "cache" / "headsq" / "quarter.nhdr"
    assert len(list(path.parent.glob("quarter.*"))) == 94


def test_a_corrupt_cached_file_is_replaced(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path / "cache"))
    path = samples.fetch("skull")
    path.write_bytes(b"not a skull")
    again = samples.fetch("skull")
    assert again.stat().st_size == 3_421_857


def test_offline_without_mirror_is_a_clear_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path / "empty"))
    monkeypatch.setenv("WORKBENCH_SAMPLE_MIRRORS", str(tmp_path / "nowhere"))
    with pytest.raises(WorkbenchError, match="skull.obj"):
        samples.fetch("skull")
    with pytest.raises(WorkbenchError, match="unknown sample"):
        samples.fetch("elephant")
