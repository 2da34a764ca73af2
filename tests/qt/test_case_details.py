"""File ▸ Case details… (issue 33): the examiner and the notes, one undo step, on the report.

The dialog is driven as a user would leave it (fields filled, OK) but from
code: opened from its File-menu action, filled, ``accept()``.  The skull is
the built-in demo case (the female reference skull, mm), reconstructed and
exported by the window as in ``test_same_outputs.py``.
"""

from __future__ import annotations

import json
import os

import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

pytestmark = pytest.mark.gui

EXAMINER = "A. Kähler-Öztürk"
NOTES = "skull received sealed, 2026-03-02"


def _fill(window, examiner: str, notes: str, *, ok: bool = True):
    """Open the dialog from File ▸ Case details…, fill it and press OK (or Cancel)."""
    action = window.actions_by_id["case_details"]
    assert action in window.menuBar().actions()[0].menu().actions()  # in the File menu
    action.trigger()
    dialog = window.case_details
    assert dialog.isVisible() and dialog.examiner.text() == window.document.case.meta.examiner
    dialog.examiner.setText(examiner)
    dialog.notes.setPlainText(notes)
    (dialog.accept if ok else dialog.reject)()
    assert not dialog.isVisible()
    return dialog


def test_the_dialog_sets_examiner_and_notes_as_one_undo_step(qtbot, window) -> None:
    meta = window.document.case.meta
    assert meta.examiner == "" and meta.notes == ""
    steps = len(window.document.stack)
    _fill(window, EXAMINER, "not kept", ok=False)  # Cancel: nothing changes
    assert window.document.case.meta.examiner == "" and len(window.document.stack) == steps
    _fill(window, f"  {EXAMINER} ", NOTES + "\n\n")
    meta = window.document.case.meta
    assert (meta.examiner, meta.notes) == (EXAMINER, NOTES)  # trimmed
    assert len(window.document.stack) == steps + 1
    assert window.actions_by_id["undo"].text() == "&Undo Edit case details"
    assert "*" in window.windowTitle()
    record = window.document.case.audit.records[-1]
    assert record["command"] == "SetCaseDetails" and record["action"] == "do"
    assert record["parameters"] == {"examiner": EXAMINER, "notes": NOTES}
    _fill(window, EXAMINER, NOTES)  # nothing changed: no step
    assert len(window.document.stack) == steps + 1

    window.undo()  # both fields at once
    meta = window.document.case.meta
    assert (meta.examiner, meta.notes) == ("", "")
    assert window.document.case.audit.records[-1]["action"] == "undo"
    window.redo()
    meta = window.document.case.meta
    assert (meta.examiner, meta.notes) == (EXAMINER, NOTES)
    assert window.document.case.audit.records[-1]["action"] == "redo"


def test_the_examiner_reaches_the_exported_report(qtbot, window, tmp_path, head_female) -> None:
    """Set after the fit (which it does not make stale), changed, undone and redone: the
    exported report names the examiner the case has at export, in JSON and on page 1."""
    import pypdf

    from workbench.io.meshes import write_mesh
    from workbench.services.templates.reference_parts import skull_surface

    skull = write_mesh(tmp_path / "skull.ply", skull_surface(head_female))
    window.open_skull(skull, units="mm")
    assert window.wait_idle(60) and not window.errors, window.errors
    _fill(window, "First Name", "")  # before the fit: the fit reads it too
    window.reconstruct()
    assert window.wait_idle(300) and not window.errors, window.errors
    fit = window.fit
    assert fit is not None
    _fill(window, EXAMINER, NOTES)
    window.undo()
    window.redo()
    assert window.fit is fit  # the case details are not an input of the fit
    assert window.export_to(tmp_path / "out")
    assert window.wait_idle(300) and not window.errors, window.errors
    report = json.loads((tmp_path / "out" / "report.json").read_text(encoding="utf-8"))
    assert report["examiner"] == EXAMINER
    first = pypdf.PdfReader(tmp_path / "out" / "report.pdf").pages[0].extract_text()
    assert f"Examiner {EXAMINER}" in " ".join(first.split())
