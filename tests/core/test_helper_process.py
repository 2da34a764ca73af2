"""The helper process that runs GIL-holding decimation away from the GUI's process."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core import helper_process
from workbench.core.isosurface import decimate
from workbench.io.meshes import read_mesh

DECIMATE = "workbench.core.isosurface:decimate"


@pytest.fixture(scope="module")
def skull(skull_obj):
    return read_mesh(skull_obj, units="auto", scale=15.0).mesh


def test_same_result_as_in_process(skull, monkeypatch) -> None:
    monkeypatch.delenv("WORKBENCH_NO_HELPER_PROCESS", raising=False)
    v, f = helper_process.call(DECIMATE, skull.vertices, skull.faces, 20_000)
    assert helper_process.status() == ""
    assert helper_process._child is not None and helper_process._child.poll() is None
    v_ref, f_ref = decimate(skull.vertices, skull.faces, 20_000)
    np.testing.assert_array_equal(f, f_ref)
    np.testing.assert_allclose(v, v_ref)
    assert 18_000 <= len(f) <= 20_000 and len(v) < skull.n_vertices


def test_errors_come_back_and_other_functions_are_refused(monkeypatch) -> None:
    monkeypatch.delenv("WORKBENCH_NO_HELPER_PROCESS", raising=False)
    with pytest.raises(ValueError, match="may not run"):
        helper_process.call("os:system", "true")
    not_faces = [["a", "b", "c"]]  # the library's own ValueError comes back
    with pytest.raises(ValueError):
        helper_process.call(DECIMATE, np.zeros((3, 3)), not_faces, 0)
    assert helper_process._child is not None and helper_process._child.poll() is None


def test_a_dead_child_is_replaced_and_a_missing_one_falls_back(skull, monkeypatch) -> None:
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


def test_run_stays_in_process_unless_the_thread_opted_in(skull, monkeypatch) -> None:
    """Scripts and the command line never start a second process; the
    window's worker threads (which call offload_here) use the helper."""
    import threading

    monkeypatch.delenv("WORKBENCH_NO_HELPER_PROCESS", raising=False)
    helper_process._stop()
    _, f = helper_process.run(DECIMATE, skull.vertices, skull.faces, 30_000)
    assert len(f) <= 30_000 and helper_process._child is None and not helper_process.offloading()

    seen = {}

    def worker() -> None:
        helper_process.offload_here()
        seen["offloading"] = helper_process.offloading()
        seen["faces"] = len(helper_process.run(DECIMATE, skull.vertices, skull.faces, 30_000)[1])
        seen["child"] = helper_process._child

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen["offloading"] and seen["faces"] <= 30_000 and seen["child"] is not None
    assert not helper_process.offloading()  # per thread: this one did not opt in


def test_only_marked_workbench_functions_may_run() -> None:
    for name in (
        "os:system",
        "workbench.core.mesh:Mesh",
        "workbench.core.isosurface:nothing",
        "workbench.core.isosurface",
        "builtins:eval",
    ):
        with pytest.raises(ValueError, match="may not run"):
            helper_process._resolve(name)
    assert helper_process._resolve(DECIMATE) is decimate


def test_no_fallback_raises_instead_of_running_here(skull, monkeypatch) -> None:
    """``fallback=False`` (a worker thread that must not run the function itself): no
    helper means an error, never an in-process run."""
    helper_process._stop()
    monkeypatch.setattr(helper_process.sys, "executable", "/nonexistent/python")
    with pytest.raises(RuntimeError, match="could not start"):
        helper_process.call(DECIMATE, skull.vertices, skull.faces, 30_000, fallback=False)
    assert helper_process._child is None
    monkeypatch.setenv("WORKBENCH_NO_HELPER_PROCESS", "1")
    with pytest.raises(RuntimeError, match="switched off"):
        helper_process.call(DECIMATE, skull.vertices, skull.faces, 30_000, fallback=False)
