"""Opening a case in the window reports its audit chain; a tampered log is refused."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from workbench.commands.case_edits import AddEvidence, SetParameter, SetSpecimen
from workbench.commands.stack import CommandStack
from workbench.core.mesh import Mesh
from workbench.io.case_file import save_case
from workbench.model.case import Case
from workbench.model.evidence import EvidenceFile

OBJ = b"v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def _case_file(tmp_path: Path) -> Path:
    skull = tmp_path / "skull.obj"
    skull.write_bytes(OBJ)
    mesh = Mesh(
        np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], float),
        np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]),
    )
    case = Case()
    stack = CommandStack(case)
    stack.push(AddEvidence(EvidenceFile.from_path(skull, "skull_mesh")))
    stack.push(SetSpecimen(mesh, "mm"))
    stack.push(SetParameter("template_hash", "ab" * 32))  # as `workbench reconstruct` leaves
    return save_case(case, tmp_path / "case.fcase", stack)


def _wait(qtbot, window) -> None:
    qtbot.waitUntil(lambda: not window.busy, timeout=20_000)


def test_open_reports_the_chain_and_the_missing_face(qtbot, window, tmp_path) -> None:
    path = _case_file(tmp_path)
    window.open_case(path)
    _wait(qtbot, window)
    assert not window.errors, window.errors
    assert any("audit log verified (4 records)" in m for m in window.messages), window.messages
    assert any(
        "case.json verified (case.json is as the workbench wrote it" in m for m in window.messages
    )
    assert "audit log verified (4 records)" in window.status_label.text()
    assert any("Reconstruct face" in m for m in window.messages)


def test_open_refuses_an_edited_log(qtbot, window, tmp_path) -> None:
    path = _case_file(tmp_path)
    with zipfile.ZipFile(path) as source:
        members = {n: source.read(n) for n in source.namelist()}
    lines = members["audit.jsonl"].splitlines(True)
    lines[1] = lines[1].replace(b'"do"', b'"undo"')
    members["audit.jsonl"] = b"".join(lines)
    with zipfile.ZipFile(path, "w") as target:
        for name, data in members.items():
            target.writestr(name, data)
    window.open_case(path)
    _wait(qtbot, window)
    assert window.errors and "record 1" in window.errors[-1] and "edited" in window.errors[-1]
    assert window.document.path != path


def test_open_refuses_an_edited_case_json(qtbot, window, tmp_path) -> None:
    """case.json changed by hand after the last save: the window refuses it, naming the edit."""
    path = _case_file(tmp_path)
    with zipfile.ZipFile(path) as source:
        members = {n: source.read(n) for n in source.namelist()}
    members["case.json"] = members["case.json"].replace(b'"examiner": "', b'"examiner": "X', 1)
    assert b'"examiner": "X' in members["case.json"]
    with zipfile.ZipFile(path, "w") as target:
        for name, data in members.items():
            target.writestr(name, data)
    window.open_case(path)
    _wait(qtbot, window)
    assert window.errors and "changed outside the workbench" in window.errors[-1], window.errors
