"""The workbench's thread pools follow WORKBENCH_THREADS / OMP_NUM_THREADS (batch workers: 1)."""

from __future__ import annotations

import os

import pytest

from workbench.core.threads import worker_count


@pytest.mark.parametrize(
    "env,expected",
    [
        ({}, os.cpu_count() or 1),
        ({"OMP_NUM_THREADS": "1"}, 1),
        ({"WORKBENCH_THREADS": "1", "OMP_NUM_THREADS": "8"}, 1),
        ({"OMP_NUM_THREADS": "999"}, os.cpu_count() or 1),
        ({"OMP_NUM_THREADS": "0"}, 1),
        ({"OMP_NUM_THREADS": "lots"}, os.cpu_count() or 1),
    ],
)
def test_worker_count(monkeypatch: pytest.MonkeyPatch, env, expected) -> None:
    for name in ("WORKBENCH_THREADS", "OMP_NUM_THREADS"):
        monkeypatch.delenv(name, raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    assert worker_count() == expected
