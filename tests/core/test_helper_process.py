"""The helper process that runs GIL-holding decimation away from the GUI's process."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core import helper_process
from workbench.core.isosurface import decimate
from workbench.io.meshes import read_mesh

DECIMATE = "workbench.core.isosurface:decimate"


@pytest.fixture(scope="module")
def skull(skull_obj):  # noqa: ANN001
    return read_mesh(skull_obj, units="auto", scale=15.0).mesh


def test_same_result_as_in_process(skull, monkeypatch) -> None:  # noqa: ANN001
    monkeypatch.delenv("WORKBENCH_NO_HELPER_PROCESS", raising=False)
    v, f = helper_process.call(DECIMATE, skull.vertices, skull.faces, 20_000)
    assert helper_process.status() == ""
    assert helper_process._child is not None and helper_process._child.poll() is None
    v_ref, f_ref = decimate(skull.vertices, skull.faces, 20_000)
    np.testing.assert_array_equal(f, f_ref)
    np.testing.assert_allclose(v, v_ref)
    assert 18_000 <= len(f) <= 20_000 and len(v) < skull.n_vertices


def test_errors_come_back_and_other_functions_are_refused(monkeypatch) -> None:  # noqa: ANN001
    monkeypatch.delenv("WORKBENCH_NO_HELPER_PROCESS", raising=False)
    with pytest.raises(ValueError, match="may not run"):
        helper_process.call("os:system", "true")
    not_faces = [["a", "b", "c"]]   # the library's own ValueError comes back
    with pytest.raises(ValueError):
        helper_process.call(DECIMATE, np.zeros((3, 3)), not_faces, 0)
    assert helper_process._child is not None and helper_process._child.poll() is None


def test_a_dead_child_is_replaced_and_a_missing_one_falls_back(skull, monkeypatch) -> None:  # noqa: ANN001
    monkeypatch.delenv("WORKBENCH_NO_HELPER_PROCESS", raising=False)
    helper_process.call(DECIMATE, skull.vertices, skull.faces, 30_000)
    first = helper_process._child
    first.kill()
    first.wait()
    _, f = helper_process.call(DECIMATE, skull.vertices, skull.faces, 30_000)
    assert helper_process._child is not first and len(f) <= 30_000
    assert helper_process.status() == ""

    helper_process._stop()
    monkeypatch.setattr(helper_process.sys, "executable", "/nonexistent/python")
    _, f = helper_process.call(DECIMATE, skull.vertices, skull.faces, 30_000)
    assert len(f) <= 30_000 and helper_process._child is None
    assert "in-process" in helper_process.status()
