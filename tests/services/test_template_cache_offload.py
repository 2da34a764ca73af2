"""The window's worker threads build the reference head in the helper process.

Building it keeps the GIL for up to ~0.5 s at a time (MINPACK, decimation),
which would freeze the window; on a thread that offloads
(``helper_process.offload_here``) the build runs in the helper process and
the thread reads the cached pack.
"""

from __future__ import annotations

import threading

import numpy as np

from workbench.core import helper_process
from workbench.services.templates import template as template_module
from workbench.services.templates.cache import cached_folder, reference_head


def test_a_worker_thread_gets_the_head_built_by_the_helper_process(
    tmp_path, monkeypatch, head_female
) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("WORKBENCH_NO_HELPER_PROCESS", raising=False)

    def not_here(*_a, **_k):
        raise AssertionError("the head was built in the window's process")

    monkeypatch.setattr(template_module, "build_reference_head", not_here)
    out: dict = {}

    def worker() -> None:
        helper_process.offload_here()
        try:
            out["head"] = reference_head("female")
        except BaseException as exc:  # noqa: BLE001 - reported below
            out["error"] = exc

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert "error" not in out, out.get("error")
    assert (cached_folder("female", tmp_path / "templates") / "template.json").is_file()
    head = out["head"]
    assert head.sex == head_female.sex == "female"
    np.testing.assert_allclose(head.skin.vertices, head_female.skin.vertices, atol=1e-4)
    assert set(head.meshes) == set(head_female.meshes)
    assert helper_process.status() == ""
