"""Autosave and crash recovery in the window, under Xvfb (QT_QPA_PLATFORM=xcb), real skull.

A "crash" is simulated by stopping a window's autosaver without the
clean-close path (:meth:`Autosaver.abandon`) and giving its sidecar the pid
of a process that has exited; a second window then finds and recovers it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

from PySide6.QtWidgets import QMessageBox

from workbench.commands.reconstruction_setup import SetDowelSettings
from workbench.io.case_file import evidence_bytes, load_case
from workbench.qt import autosave, dialogs
from workbench.qt.autosave import find_recoverable, recover

pytestmark = pytest.mark.gui


@pytest.fixture
def folder(tmp_path, monkeypatch) -> Path:
    path = tmp_path / "autosave"
    monkeypatch.setenv("WORKBENCH_AUTOSAVE_DIR", str(path))
    monkeypatch.setenv("WORKBENCH_AUTOSAVE_S", "0")  # tests call autosave() themselves
    return path


@pytest.fixture
def skull_copy(skull_obj, tmp_path) -> Path:
    """A private copy of the skull: deleting it shows the evidence lives on in the snapshot."""
    (tmp_path / "scan").mkdir()
    return Path(shutil.copy(skull_obj, tmp_path / "scan" / "skull.obj"))


@pytest.fixture
def make_window(new_window, folder):
    """Windows made after the autosave folder is set (see ``folder``)."""
    return lambda: new_window(1000, 700)


@pytest.fixture
def window(make_window):
    return make_window()


def _open(qtbot, window, path) -> None:
    window.open_skull(path, scale=15.0)
    qtbot.waitUntil(lambda: not window.busy, timeout=30_000)
    assert not window.errors, window.errors
    assert window.document.has_specimen


def _edit(qtbot, window) -> None:
    """Place glabella with a pick on the skull and set the sex of the dowels (two undo steps)."""
    window.landmarks_panel.select("g")
    window.on_pick(np.array(window.document.case.specimen.mesh.vertices[1234]))
    assert window.document.push(SetDowelSettings(sex="female"))
    qtbot.waitUntil(lambda: not window.busy, timeout=30_000)
    assert window.document.is_dirty


def _dead_pid() -> int:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


def _crash(window) -> tuple:
    """Stop ``window`` as a crash would: files left, owner pid gone. Returns its case."""
    saver = window.autosaver
    saver.abandon()
    sidecar = json.loads(saver.sidecar_path.read_text(encoding="utf-8"))
    sidecar["pid"] = _dead_pid()
    saver.sidecar_path.write_text(json.dumps(sidecar), encoding="utf-8")
    case = window.document.case
    window.close()  # the clean-close path no longer deletes anything
    assert saver.snapshot_path.is_file() and saver.sidecar_path.is_file()
    return case, saver


def test_crash_then_recover_an_untitled_case(qtbot, make_window, folder, skull_copy, tmp_path):
    original_bytes = skull_copy.read_bytes()
    first = make_window()
    _open(qtbot, first, skull_copy)
    assert not first.autosaver.autosave(wait=True)  # clean: nothing to save
    assert not first.autosaver.has_snapshot
    _edit(qtbot, first)
    assert first.autosaver.autosave(wait=True)
    assert first.autosaver.last_error is None
    assert not first.autosaver.autosave(wait=True)  # no change since the last snapshot
    info = json.loads(first.autosaver.sidecar_path.read_text(encoding="utf-8"))
    assert info["pid"] == os.getpid() and info["original_path"] is None
    assert info["title"] == "untitled case" and info["specimen"] == "skull.obj"
    assert info["undo_steps"] == len(first.document.stack) == 2
    assert first.autosaver.timings["gui"] < 50.0  # the frozen copy; the write is in a worker
    # a running session is never offered
    assert find_recoverable(folder) == []

    crashed, saver = _crash(first)
    skull_copy.unlink()  # the scan is gone: only the snapshot holds the evidence now

    second = make_window()
    assert second.autosaver.session != saver.session
    entries = find_recoverable(folder)
    assert len(entries) == 1
    entry = entries[0]
    assert entry.recoverable and entry.problem is None
    assert entry.snapshot == saver.snapshot_path and entry.original_path is None
    assert entry.title == "untitled case" and entry.specimen == "skull.obj"
    assert entry.undo_steps == 2
    assert "Recover unsaved work from" in entry.question() and "untitled case" in entry.question()

    assert recover(second, entry)
    doc = second.document
    assert doc.case.equals(crashed)
    g = doc.case.landmarks["skull"]["g"]
    np.testing.assert_array_equal(g.position, crashed.specimen.mesh.vertices[1234])
    assert g.status == "placed"
    assert doc.case.dowels.sex == "female"
    assert doc.case.specimen.mesh.equals(crashed.specimen.mesh)
    assert doc.case.specimen.mesh.n_faces == 100_002
    assert len(second.scene.actors("skull")) == 1
    assert doc.is_dirty and "*" in second.windowTitle() and doc.path is None
    assert not doc.stack.can_undo  # the lost session's history is not recovered
    last = doc.case.audit.records[-1]
    assert last["operation"] == "Recover unsaved work"
    assert last["parameters"]["snapshot"] == saver.snapshot_path.name
    # the recovered snapshot became this session's own; nothing else is offered
    assert not saver.snapshot_path.exists() and second.autosaver.has_snapshot
    assert find_recoverable(folder) == []
    assert not second.errors, second.errors

    target = tmp_path / "recovered.fcase"
    assert second.save_to(target)
    assert not doc.is_dirty
    assert list(folder.iterdir()) == []  # saved: the snapshot is gone
    assert evidence_bytes(target, "skull.obj") == original_bytes
    reopened = load_case(target).case
    assert reopened.landmarks["skull"]["g"].status == "placed"
    assert reopened.dowels.sex == "female"


def test_recovered_case_saves_to_its_original_file_only_when_saved(
    qtbot, make_window, folder, skull_copy, tmp_path
):
    first = make_window()
    _open(qtbot, first, skull_copy)
    case_path = tmp_path / "case.fcase"
    assert first.save_to(case_path)
    saved_bytes = case_path.read_bytes()
    _edit(qtbot, first)
    first.autosaver.autosave(wait=True)
    _crashed, _saver = _crash(first)

    second = make_window()
    (entry,) = find_recoverable(folder)
    assert entry.original_path == case_path.resolve() and entry.title == "case.fcase"
    assert recover(second, entry)
    assert second.document.path == case_path.resolve()
    assert "case.fcase *" in second.windowTitle()
    assert case_path.read_bytes() == saved_bytes  # nothing written before the user saves

    second.autosaver.autosave(wait=True)  # the recovered session autosaves as any other
    assert second.autosaver.has_snapshot
    assert second.save()  # Save (not Save As): the original file
    assert list(folder.iterdir()) == []
    loaded = load_case(case_path)
    assert loaded.case.dowels.sex == "female"
    assert loaded.case.landmarks["skull"]["g"].status == "placed"
    actions = [(r["action"], r["operation"]) for r in loaded.audit_records]
    assert ("do", "Recover unsaved work") in actions and actions[-1][0] == "save"
    assert not second.errors, second.errors


def test_clean_close_save_discard_and_undo_remove_the_snapshot(
    qtbot, make_window, folder, skull_copy, tmp_path, monkeypatch
):
    window = make_window()
    _open(qtbot, window, skull_copy)
    saver = window.autosaver
    _edit(qtbot, window)
    assert saver.autosave(wait=True) and saver.has_snapshot
    # undone back to the opened state: clean, the snapshot goes at the next tick
    window.undo()
    window.undo()
    assert not window.document.is_dirty
    saver.autosave(wait=True)
    assert not saver.has_snapshot and not saver.sidecar_path.exists()

    # a deliberate Discard
    window.redo()
    assert saver.autosave(wait=True) and saver.has_snapshot
    monkeypatch.setattr(dialogs, "ask_save_changes", lambda *_a: QMessageBox.StandardButton.Discard)
    window.interactive = True
    try:
        assert window.may_discard()
    finally:
        window.interactive = False
    assert not saver.has_snapshot

    # a failed save keeps it; a successful one removes it
    assert saver.autosave(wait=True) and saver.has_snapshot
    assert not window.save_to(tmp_path / "no_such_folder" / "case.fcase")
    assert saver.has_snapshot
    window.errors.clear()
    assert window.save_to(tmp_path / "case.fcase") and not saver.has_snapshot

    # a clean close (with unsaved work written) removes it
    window.document.push(SetDowelSettings(sex="male"))
    assert saver.autosave(wait=True) and saver.has_snapshot
    window.close()
    assert list(folder.iterdir()) == []


def test_timer_writes_in_the_worker_and_env_zero_disables(
    qtbot, make_window, folder, skull_copy, monkeypatch
):
    monkeypatch.setenv("WORKBENCH_AUTOSAVE_S", "0.2")
    window = make_window()
    assert window.autosaver.timer.isActive() and window.autosaver.timer.interval() == 200
    _open(qtbot, window, skull_copy)
    written = []
    window.autosaver.snapshot_written.connect(written.append)
    _edit(qtbot, window)
    qtbot.waitUntil(lambda: bool(written), timeout=10_000)
    assert written == [str(window.autosaver.snapshot_path)]
    assert load_case(window.autosaver.snapshot_path).case.equals(window.document.case)
    assert window.autosaver.timings["total"] > window.autosaver.timings["gui"]
    window.close()
    assert list(folder.iterdir()) == []

    monkeypatch.setenv("WORKBENCH_AUTOSAVE_S", "0")
    assert not make_window().autosaver.timer.isActive()


def test_damaged_snapshots_are_listed_with_a_reason(
    qtbot, make_window, folder, skull_copy, tmp_path
):
    window = make_window()
    _open(qtbot, window, skull_copy)
    _edit(qtbot, window)
    window.autosaver.autosave(wait=True)
    _case, saver = _crash(window)
    # truncate the snapshot; add a sidecar that is not JSON and a snapshot with no sidecar
    data = saver.snapshot_path.read_bytes()
    saver.snapshot_path.write_bytes(data[: len(data) // 2])
    (folder / "autosave-garbled.json").write_text("{not json", encoding="utf-8")
    shutil.copy(saver.snapshot_path, folder / "autosave-lonely.fcase")

    entries = find_recoverable(folder)
    assert len(entries) == 3 and not any(e.recoverable for e in entries)
    reasons = {e.snapshot.name: e.problem for e in entries}
    assert "damaged or truncated" in reasons[saver.snapshot_path.name]
    assert "not valid JSON" in reasons["autosave-garbled.fcase"]
    assert "description file is missing" in reasons["autosave-lonely.fcase"]
    assert not any("Traceback" in r for r in reasons.values())

    other = make_window()
    assert not autosave.offer_recovery(other)  # non-interactive: never a dialog
    assert sum("cannot be recovered" in m for m in other.messages) == 3
    assert not recover(other, entries[0])
    assert "Could not recover" in other.errors[-1]
    assert len(list(folder.iterdir())) == 4  # left on disk for a person to look at


def test_reused_pid_counts_as_gone_and_the_offer_asks(
    qtbot, make_window, folder, skull_copy, monkeypatch
):
    window = make_window()
    _open(qtbot, window, skull_copy)
    _edit(qtbot, window)
    window.autosaver.autosave(wait=True)
    saver = window.autosaver
    saver.abandon()
    crashed = window.document.case
    # our own pid, but a session that started before this process: an earlier process
    info = json.loads(saver.sidecar_path.read_text(encoding="utf-8"))
    info["session_started"] = autosave._IMPORTED_AT - 3600.0
    saver.sidecar_path.write_text(json.dumps(info), encoding="utf-8")
    window.close()

    other = make_window()
    shown = []

    def click_later(box) -> int:
        shown.append((box.text(), box.informativeText(), [b.text() for b in box.buttons()]))
        next(b for b in box.buttons() if b.text() == "Later").click()
        return 0

    monkeypatch.setattr(QMessageBox, "exec", click_later)
    (entry,) = find_recoverable(folder)
    assert autosave.ask_recovery(other, entry) == autosave.LATER
    text, details, buttons = shown[0]
    assert text == f"Recover unsaved work from {entry.when} (untitled case)?"
    assert "skull.obj" in details and "never saved" in details
    assert sorted(buttons) == ["Discard", "Later", "Recover"]

    asked = []
    monkeypatch.setattr(
        autosave, "ask_recovery", lambda _parent, entry: asked.append(entry) or autosave.LATER
    )
    other.interactive = True
    try:
        assert not autosave.offer_recovery(other)  # Later: kept for the next start
        assert len(asked) == 1 and saver.snapshot_path.exists()
        monkeypatch.setattr(autosave, "ask_recovery", lambda *_a: autosave.RECOVER)
        assert autosave.offer_recovery(other)
    finally:
        other.interactive = False
    assert other.document.case.equals(crashed) and other.document.is_dirty
    assert not saver.snapshot_path.exists()


def test_a_failed_autosave_is_a_message_and_the_case_is_unaffected(make_window, folder, tmp_path):
    folder.parent.mkdir(exist_ok=True)
    folder.write_text("a file where the autosave folder should be", encoding="utf-8")
    window = make_window()
    assert window.document.push(SetDowelSettings(sex="female"))
    assert window.autosaver.autosave(wait=True)
    assert window.autosaver.last_error.startswith("Autosave failed")
    assert any(m.startswith("Autosave failed") for m in window.messages)
    assert window.status_label.text().startswith("Autosave failed")
    assert not window.errors and window.document.is_dirty
    assert window.document.case.dowels.sex == "female"
    window.close()  # closes cleanly although nothing could be written
