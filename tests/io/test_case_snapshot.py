"""Snapshots for autosave (``write_case_snapshot``): a loadable case file with no side effects."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from workbench.commands.case_edits import SetParameter
from workbench.commands.landmarks import PlaceLandmark
from workbench.commands.reconstruction_setup import SetDowelSettings
from workbench.commands.stack import CommandStack
from workbench.io.case_file import (
    CaseFileError,
    detached_copy,
    evidence_bytes,
    load_case,
    read_case_json,
    save_case,
    write_case_snapshot,
)
from workbench.model.audit import parse_records
from workbench.model.case import Case
from workbench.model.state import states_equal
from workbench.services.case.case_setup import start_case_from_skull


@pytest.fixture
def skull_copy(skull_obj: Path, tmp_path: Path) -> Path:
    """A private copy of the 100k skull, so a test can delete the "original" evidence."""
    folder = tmp_path / "scan"
    folder.mkdir()
    return Path(shutil.copy(skull_obj, folder / "skull.obj"))


@pytest.fixture
def edited(skull_copy: Path) -> tuple[Case, CommandStack]:
    """A never-saved case: the skull (x15 to mm), a placed landmark, dowels, a parameter."""
    opened = start_case_from_skull(skull_copy, scale=15.0, examiner="A. Examiner")
    case, stack = opened.case, opened.stack
    stack.push(PlaceLandmark("skull", "g", case.specimen.mesh.vertices[123]))
    stack.push(SetDowelSettings(table="stephan_2013"))
    stack.push(SetParameter("template_id", "male-v1"))
    return case, stack


def _observable(case: Case) -> dict:
    """Everything a snapshot must leave alone."""
    return {
        "state": case.to_state(),
        "meta": case.meta.to_state(),
        "records": case.audit.records,
        "pending": case.audit.pending,
        "persisted": case.audit.persisted_bytes,
        "source": case.source_path,
        "retained": dict(case.retained_evidence),
    }


def _same(before: dict, after: dict) -> None:
    assert states_equal(before["state"], after["state"])
    for key in ("meta", "records", "pending", "persisted", "source", "retained"):
        assert before[key] == after[key], key


def test_snapshot_leaves_case_audit_and_stack_untouched(edited, tmp_path: Path) -> None:
    case, stack = edited
    before, steps = _observable(case), len(stack)
    assert stack.is_dirty and len(case.audit.pending) > 0
    path = write_case_snapshot(case, tmp_path / "snap.fcase")
    _same(before, _observable(case))
    assert stack.is_dirty and len(stack) == steps and stack.can_undo
    assert case.source_path is None

    loaded = load_case(path)
    assert not loaded.tampered
    assert loaded.case.equals(case)
    # the log as it was, and no "save" record
    assert loaded.audit_records == case.audit.records
    assert all(r["action"] != "save" for r in loaded.audit_records)
    assert loaded.case.meta.to_state() == case.meta.to_state()
    assert read_case_json(path)["meta"]["case_id"] == case.meta.case_id


def test_snapshot_over_itself_and_after_a_save(edited, tmp_path: Path) -> None:
    case, stack = edited
    snap = tmp_path / "snap.fcase"
    write_case_snapshot(case, snap)
    stack.push(PlaceLandmark("skull", "n", case.specimen.mesh.vertices[456]))
    write_case_snapshot(case, snap)  # overwrites its own earlier snapshot
    assert load_case(snap).case.equals(case)

    saved = save_case(case, tmp_path / "case.fcase", stack)
    persisted = case.audit.persisted_bytes
    stack.push(SetDowelSettings(sex="female"))
    before = _observable(case)
    write_case_snapshot(case, snap)
    _same(before, _observable(case))
    assert case.source_path == saved and case.audit.persisted_bytes == persisted
    with zipfile.ZipFile(snap) as archive:
        audit = archive.read("audit.jsonl")
    # the log as encode() gives it, its last record sealing the snapshot's case.json
    seal = parse_records(audit)[-1]["content_sha256"]
    assert audit.startswith(persisted) and audit == case.audit.encode(content=seal)
    # the snapshot is never written over the saved file
    assert load_case(saved).case.dowels.sex == "male"


def test_evidence_survives_in_the_snapshot_when_the_original_is_gone(
    edited, skull_copy: Path, tmp_path: Path
) -> None:
    case, _stack = edited
    original = skull_copy.read_bytes()
    snap = write_case_snapshot(case, tmp_path / "snap.fcase")
    assert evidence_bytes(snap, "skull.obj") == original
    skull_copy.unlink()  # the scan was in a temporary folder, say

    loaded = load_case(snap)
    assert not loaded.tampered
    assert loaded.case.specimen.mesh.equals(case.specimen.mesh)
    # the recovered case saves normally: evidence bytes come from the snapshot
    saved = save_case(loaded.case, tmp_path / "recovered.fcase")
    assert evidence_bytes(saved, "skull.obj") == original
    reopened = load_case(saved).case
    assert reopened.meta.case_id == case.meta.case_id  # meta.modified moved on: a save
    assert states_equal(
        {k: v for k, v in reopened.to_state().items() if k != "meta"},
        {k: v for k, v in case.to_state().items() if k != "meta"},
    )


def test_evidence_missing_everywhere_is_a_readable_error(
    edited, skull_copy: Path, tmp_path: Path
) -> None:
    case, _stack = edited
    skull_copy.unlink()
    before = _observable(case)
    with pytest.raises(CaseFileError, match="no copy of evidence 'skull.obj'"):
        write_case_snapshot(case, tmp_path / "snap.fcase")
    _same(before, _observable(case))
    assert not list(tmp_path.glob("*.fcase")) and not list(tmp_path.glob(".*.tmp"))


def test_detached_copy_is_equal_and_unreachable_by_later_edits(edited, tmp_path: Path) -> None:
    case, stack = edited
    copy = detached_copy(case)
    assert copy.equals(case) and copy is not case
    assert copy.audit.encode() == case.audit.encode()
    assert dict(copy.retained_evidence) == dict(case.retained_evidence)
    assert copy.source_path == case.source_path
    assert copy.specimen.mesh is case.specimen.mesh  # shared, immutable: nothing copied
    assert not copy.specimen.mesh.vertices.flags.writeable

    stack.push(PlaceLandmark("skull", "n", case.specimen.mesh.vertices[7]))
    stack.undo()
    stack.redo()
    assert "n" in case.landmarks["skull"] and "n" not in copy.landmarks["skull"]
    assert len(copy.audit) < len(case.audit)

    loaded = load_case(write_case_snapshot(copy, tmp_path / "snap.fcase")).case
    assert "n" not in loaded.landmarks["skull"]
    np.testing.assert_array_equal(
        loaded.landmarks["skull"]["g"].position, case.landmarks["skull"]["g"].position
    )


def test_read_case_json_names_the_problem(tmp_path: Path) -> None:
    bad = tmp_path / "bad.fcase"
    bad.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(CaseFileError, match="damaged or truncated"):
        read_case_json(bad)
    with zipfile.ZipFile(tmp_path / "nojson.fcase", "w") as archive:
        archive.writestr("case.json", json.dumps([1, 2]))
    with pytest.raises(CaseFileError, match="not a JSON object"):
        read_case_json(tmp_path / "nojson.fcase")
