"""Window tests never write autosave snapshots into the user's own folder."""

from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _private_autosave(monkeypatch, tmp_path_factory):  # noqa: ANN001
    monkeypatch.setenv("WORKBENCH_AUTOSAVE_DIR", str(tmp_path_factory.mktemp("autosave")))
