"""The audit log's hash chain in a ``.fcase``: anchored at every save, verified on load."""

from __future__ import annotations

import json
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.commands.case_edits import AddEvidence, SetExaminer, SetParameter, SetSpecimen
from workbench.commands.landmarks import PlaceLandmark
from workbench.commands.reconstruction_setup import SetDowelSettings
from workbench.commands.stack import CommandStack
from workbench.core.mesh import Mesh
from workbench.io.case_file import (
    CaseFileError,
    detached_copy,
    load_case,
    save_case,
    write_case_snapshot,
)
from workbench.model.audit import (
    content_digest,
    encode_record,
    make_record,
    parse_records,
    record_hash,
)
from workbench.model.case import Case
from workbench.model.evidence import EvidenceFile
from workbench.services.case.case_setup import describe_case

OBJ = b"v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


@pytest.fixture
def saved(tmp_path: Path) -> Path:
    """A small case saved twice: 9 audit records (7 edits, 2 saves)."""
    skull = tmp_path / "skull.obj"
    skull.write_bytes(OBJ)
    mesh = Mesh(
        np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], float),
        np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]),
    )
    case = Case()
    stack = CommandStack(case)
    stack.push(SetExaminer("A. Examiner"))
    stack.push(AddEvidence(EvidenceFile.from_path(skull, "skull_mesh")))
    stack.push(SetSpecimen(mesh, "mm"))
    stack.push(PlaceLandmark("skull", "n", mesh.vertices[1]))
    path = save_case(case, tmp_path / "case.fcase", stack)
    stack.push(PlaceLandmark("skull", "g", mesh.vertices[2]))
    stack.undo()
    stack.push(SetDowelSettings(sex="female"))
    save_case(case, path, stack)
    return path


def _members(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def _rewrite(
    path: Path,
    audit: Callable[[list[bytes]], list[bytes]] | None = None,
    doc: Callable[[dict], None] | None = None,
) -> None:
    """Rewrite the zip with its audit lines and/or case.json changed (CRCs valid)."""
    members = _members(path)
    if audit is not None:
        members["audit.jsonl"] = b"".join(audit(members["audit.jsonl"].splitlines(True)))
    if doc is not None:
        state = json.loads(members["case.json"])
        doc(state)
        members["case.json"] = json.dumps(state, indent=1).encode()
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            archive.writestr(name, data)


def _records(path: Path) -> list[dict]:
    return parse_records(_members(path)["audit.jsonl"])


def _edit_line(index: int) -> Callable[[list[bytes]], list[bytes]]:
    def change(lines: list[bytes]) -> list[bytes]:
        lines[index] = lines[index].replace(b"A. Examiner", b"B. Examiner")
        return lines

    return change


def _forge(lines: list[bytes]) -> list[bytes]:
    last = parse_records(lines[-1])[0]
    forged = make_record("do", "Forged edit", "Mallory")
    forged.update(prev=record_hash(last), seq=len(lines))
    return [*lines, encode_record(forged)]


def test_saved_chain_is_anchored_and_verifies(saved: Path) -> None:
    records = _records(saved)
    assert len(records) == 9 and [r["seq"] for r in records] == list(range(9))
    anchor = json.loads(_members(saved)["case.json"])["audit_chain"]
    assert anchor == {"head": record_hash(records[-1]), "records": 9, "unchained": 0}
    loaded = load_case(saved)
    assert not loaded.tampered and loaded.evidence_status["audit.jsonl"] == "ok"
    assert loaded.audit_chain.summary() == "verified (9 records)"
    assert all("prev" not in r for r in loaded.audit_records)
    info = describe_case(saved)
    assert info["audit_chain"]["status"] == "verified (9 records)" and not info["tampered"]
    # loaded, edited and saved again: the chain goes on
    stack = CommandStack(loaded.case)
    stack.push(SetParameter("note", "x"))
    save_case(loaded.case, saved, stack)
    assert load_case(saved).audit_chain.summary() == "verified (11 records)"


def test_snapshot_is_chained_like_a_save(saved: Path, tmp_path: Path) -> None:
    case = load_case(saved).case
    CommandStack(case).push(SetParameter("note", "y"))
    snap = write_case_snapshot(case, tmp_path / "snap.fcase")
    assert load_case(snap).audit_chain.summary() == "verified (10 records)"
    assert len(case.audit.pending) == 1


TAMPERS = {
    "edited": (dict(audit=_edit_line(3)), 3, "edited"),
    "deleted in the middle": (dict(audit=lambda lines: lines[:4] + lines[5:]), 4, "missing"),
    "last deleted": (dict(audit=lambda lines: lines[:-1]), 8, "missing"),
    "swapped": (
        dict(audit=lambda lines: [*lines[:2], lines[3], lines[2], *lines[4:]]),
        2,
        "reordered",
    ),
    "forged append": (dict(audit=_forge), 9, "added after the last save"),
    "anchor edited": (dict(doc=lambda d: d["audit_chain"].update(head="0" * 64)), 8, "anchor"),
    "anchor removed": (dict(doc=lambda d: d.pop("audit_chain")), 0, "no audit chain anchor"),
}


@pytest.mark.parametrize("kind", TAMPERS)
def test_each_tamper_is_refused_then_reported(
    saved: Path, kind: str, capsys: pytest.CaptureFixture[str]
) -> None:
    change, index, words = TAMPERS[kind]
    _rewrite(saved, **change)
    before = saved.read_bytes()
    with pytest.raises(CaseFileError) as caught:
        load_case(saved)
    message = str(caught.value)
    assert str(saved) in message and "audit.jsonl" in message and words in message
    assert f"record {index}" in message, message
    records = _records(saved)
    if index < len(records) and kind not in ("deleted in the middle", "last deleted"):
        assert records[index]["time"] in message  # the first bad record's time and action

    loaded = load_case(saved, allow_tampered=True)
    assert loaded.tampered and loaded.audit_chain.index == index
    assert loaded.evidence_status["audit.jsonl"] == loaded.audit_chain.problem
    assert all(s == "ok" for m, s in loaded.evidence_status.items() if m != "audit.jsonl")
    info = describe_case(saved, allow_tampered=True)
    assert info["tampered"] and info["audit_chain"]["first_bad_record"] == index
    assert info["audit_chain"]["status"].startswith("NOT VERIFIED: ")

    assert main(["case", "info", str(saved)]) == 2
    assert f"record {index}" in capsys.readouterr().err
    assert main(["case", "info", str(saved), "--allow-tampered"]) == 0
    shown = json.loads(capsys.readouterr().out)["audit_chain"]
    assert shown["status"].startswith("NOT VERIFIED") and shown["first_bad_record"] == index
    assert saved.read_bytes() == before  # inspection never rewrites a case


def test_tamper_survives_a_save_of_the_tampered_case(saved: Path) -> None:
    _rewrite(saved, audit=_edit_line(3))
    case = load_case(saved, allow_tampered=True).case
    save_case(case, saved)
    status = load_case(saved, allow_tampered=True).audit_chain
    assert status.index == 3 and not status.ok  # a save never heals the chain


def _as_old_file(path: Path) -> None:
    """What the software wrote before the chain: no seq/prev, no anchor."""

    def strip(lines: list[bytes]) -> list[bytes]:
        out = []
        for record in parse_records(b"".join(lines)):
            record.pop("prev"), record.pop("seq")
            out.append(encode_record(record))
        return out

    _rewrite(path, audit=strip, doc=lambda d: d.pop("audit_chain"))


def test_old_case_loads_as_predating_the_chain_then_is_sealed(
    saved: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _as_old_file(saved)
    old_log = _members(saved)["audit.jsonl"]
    loaded = load_case(saved)
    assert not loaded.tampered and loaded.audit_chain.state == "unchained"
    assert loaded.audit_chain.summary() == "audit log predates the hash chain (not verifiable)"
    assert loaded.evidence_status["audit.jsonl"] == "ok"
    assert main(["case", "info", str(saved)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["audit_chain"]["status"] == "audit log predates the hash chain (not verifiable)"
    assert not info["tampered"] and len(info["audit"]) == 9

    # the next save starts the chain; the old records are kept byte for byte, sealed
    new = save_case(loaded.case, tmp_path / "new.fcase")
    assert _members(new)["audit.jsonl"].startswith(old_log)
    status = load_case(new).audit_chain
    assert status.state == "verified" and status.unchained == 9 and status.records == 10
    assert "the first 9 predate the hash chain" in status.summary()
    _rewrite(new, audit=_edit_line(2))
    with pytest.raises(CaseFileError, match="predate the chain, were edited"):
        load_case(new)


def test_damaged_log_is_still_a_damaged_log(saved: Path) -> None:
    _rewrite(saved, audit=lambda lines: [*lines[:-1], b"{oops\n"])
    with pytest.raises(CaseFileError, match="audit log is damaged"):
        load_case(saved)


def test_case_info_of_nested_parameters_is_json(
    saved: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Frozen nested values (mappingproxy) once made ``case info`` fail to print."""
    case = load_case(saved).case
    stack = CommandStack(case)
    stack.push(SetParameter("provenance", {"pack": {"id": "male", "sizes": [1, 2]}}))
    save_case(case, saved, stack)
    json.dumps(describe_case(saved))  # plain JSON, no default= needed
    assert main(["case", "info", str(saved)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["parameters"]["provenance"] == {"pack": {"id": "male", "sizes": [1, 2]}}
    assert info["audit_chain"]["status"] == "verified (11 records)"


def test_every_write_seals_case_json(saved: Path, tmp_path: Path) -> None:
    """A save and a snapshot seal case.json in their last record; both open verified."""
    records = _records(saved)
    doc = json.loads(_members(saved)["case.json"])
    assert records[-1]["content_sha256"] == content_digest(doc)
    assert all("content_sha256" not in r for r in records[:4] + records[5:-1])
    loaded = load_case(saved)
    assert loaded.content_seal.state == "verified" and loaded.evidence_status["case.json"] == "ok"
    assert describe_case(saved)["audit_chain"]["content"]["sealed_at"] == records[-1]["time"]
    CommandStack(loaded.case).push(SetParameter("note", "z"))
    snap = write_case_snapshot(detached_copy(loaded.case), tmp_path / "snap.fcase")
    assert load_case(snap).content_seal.state == "verified"
    assert _records(snap)[-1]["operation"] == "Set note" and "content_sha256" in _records(snap)[-1]


def test_indentation_alone_is_not_an_edit(saved: Path) -> None:
    _rewrite(saved, doc=lambda d: None)  # same content, written with another layout
    assert load_case(saved).content_seal.state == "verified"
