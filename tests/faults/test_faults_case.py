"""Fault corpus for case files and track files (issue 29, rows 3 and 4).

Row 3: hand edits of ``case.json`` inside a ``.fcase`` must not read as
verified, must not be sealed by a later save, and a member listed twice is
refused.  Row 4: no member may cost more than its limit (padding, zip bombs,
headers that lie), encrypted or oddly compressed members and unsafe names are
refused with a message, and deeply nested JSON is refused before decoding.

Every entry runs the command through the CLI in-process and checks the exit
status, that the message names the file and the member/problem, that no
traceback-like failure leaks out, and that the input files are unchanged.
"""

from __future__ import annotations

import hashlib
import json
import struct
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.commands.case_edits import AddEvidence, SetExaminer, SetSpecimen
from workbench.commands.landmarks import PlaceLandmark
from workbench.commands.stack import CommandStack
from workbench.core.mesh import Mesh
from workbench.io.case_file import CaseFileError, load_case, save_case, write_case_snapshot
from workbench.model.audit import CHAIN_FIELDS, AuditLog, chain_anchor, parse_records
from workbench.model.case import Case
from workbench.model.evidence import EvidenceFile

OBJ = b"v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
LEAKS = ("Traceback", "unexpected error", "RecursionError", "MemoryError")
MIB = 1024 * 1024


# ---------------------------------------------------------------- small files
def _case(folder: Path) -> Path:
    """A small saved case: a tetrahedron skull as evidence, glabella placed, one examiner."""
    skull = folder / "skull.obj"
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
    stack.push(PlaceLandmark("skull", "g", mesh.vertices[1]))
    path = save_case(case, folder / "case.fcase", stack)
    skull.unlink()  # the case file is the only copy of the evidence
    return path


Member = tuple[zipfile.ZipInfo, bytes]


def _members(path: Path) -> list[Member]:
    with zipfile.ZipFile(path) as archive:
        return [(info, archive.read(info.filename)) for info in archive.infolist()]


def _write(path: Path, members: list[Member]) -> None:
    """Rewrite ``path`` from ``members`` (CRCs valid, duplicates allowed)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "Duplicate name" is the point of some entries
        with zipfile.ZipFile(path, "w") as archive:
            for info, data in members:
                archive.writestr(info, data)


def _info(name: str, method: int = zipfile.ZIP_DEFLATED) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=(2024, 1, 1, 0, 0, 0))
    info.compress_type = method
    return info


def _edit_doc(path: Path, edit: Callable[[dict], None]) -> None:
    """Change case.json by hand, as a zip tool and a text editor would."""
    members = []
    for info, data in _members(path):
        if info.filename == "case.json":
            doc = json.loads(data)
            edit(doc)
            data = json.dumps(doc, indent=1).encode()
        members.append((info, data))
    _write(path, members)


def _move_glabella(doc: dict) -> None:
    for landmark in doc["landmarks"]["skull"]["landmarks"]:
        if landmark["code"] == "g":
            landmark["position"][0] += 10.0  # 10 mm


def _rename_examiner(doc: dict) -> None:
    doc["meta"]["examiner"] = "B. Someone Else"


def _replace(path: Path, name: str, data: bytes, method: int = zipfile.ZIP_DEFLATED) -> None:
    _write(
        path,
        [
            (_info(name, method), data) if info.filename == name else (info, old)
            for info, old in _members(path)
        ],
    )


def _add(path: Path, name: str, data: bytes) -> None:
    _write(path, [*_members(path), (_info(name), data)])


def _deflated_run(path: Path, name: str, prefix: bytes, run: bytes, size: int) -> None:
    """Replace member ``name`` by ``prefix`` + ``size`` bytes of ``run``, deflated hard."""
    members = _members(path)
    with zipfile.ZipFile(path, "w") as archive:
        for info, data in members:
            if info.filename != name:
                archive.writestr(info, data)
                continue
            target = _info(name)
            with archive.open(target, "w", force_zip64=True) as stream:
                stream.write(prefix)
                block = run * (MIB // len(run))
                for _ in range(size // MIB):
                    stream.write(block)


def _patch_headers(path: Path, name: str, change: Callable[[bytearray, int, bool], None]) -> None:
    """Change the central and local headers of member ``name`` in place (bytes)."""
    raw = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as archive:
        local = archive.getinfo(name).header_offset
    encoded = name.encode()
    central = raw.find(b"PK\x01\x02")
    while central >= 0:
        length = struct.unpack_from("<H", raw, central + 28)[0]
        if raw[central + 46 : central + 46 + length] == encoded:
            break
        central = raw.find(b"PK\x01\x02", central + 4)
    assert central >= 0 and raw[local : local + 4] == b"PK\x03\x04"
    change(raw, central, True)
    change(raw, local, False)
    path.write_bytes(bytes(raw))


def _set_encrypted(raw: bytearray, at: int, central: bool) -> None:
    flags = at + (8 if central else 6)
    struct.pack_into("<H", raw, flags, struct.unpack_from("<H", raw, flags)[0] | 0x1)


def _lie_about_size(raw: bytearray, at: int, central: bool) -> None:
    """Claim 2,000 bytes unpacked, whatever the stream holds."""
    struct.pack_into("<L", raw, at + (24 if central else 22), 2000)


def _as_previous_version(path: Path) -> None:
    """The case as the previous version wrote it: chained and anchored, but no content seal."""
    members = []
    doc = json.loads(next(d for i, d in _members(path) if i.filename == "case.json"))
    log = AuditLog(case_id=doc["meta"]["case_id"])
    for info, data in _members(path):
        if info.filename == "audit.jsonl":
            for record in parse_records(data):
                log.append({k: v for k, v in record.items() if k not in CHAIN_FIELDS})
            data = log.encode()
            doc["audit_chain"] = chain_anchor(parse_records(data))
        members.append((info, data))
    _write(
        path,
        [
            (i, json.dumps(doc, indent=1).encode() if i.filename == "case.json" else d)
            for i, d in members
        ],
    )


def _padded_with_lying_header(path: Path) -> None:
    _deflated_run(path, "case.json", b"{", b" ", 32 * MIB)
    _patch_headers(path, "case.json", _lie_about_size)


# ---------------------------------------------------------------- the corpus
@dataclass(frozen=True)
class Fault:
    """One hostile input: how to make it, the command, and what must be said."""

    make: Callable[[Path], object]
    argv: tuple[str, ...]
    status: int
    says: tuple[str, ...]
    stream: str = "err"
    then: Callable[[Path, str], None] | None = field(default=None)


def _info_json(out: str) -> dict:
    return json.loads(out)


def _reported_edit(case: Path, out: str) -> None:
    """--allow-tampered shows the edit; the case is never sealed again."""
    info = _info_json(out)
    content = info["audit_chain"]["content"]
    assert info["tampered"] is True and content["state"] == "changed"
    assert content["status"].startswith("NOT VERIFIED: case.json was changed outside")
    loaded = load_case(case, allow_tampered=True)
    assert loaded.tampered and loaded.content_seal.state == "changed"
    for write in (save_case, write_case_snapshot):
        with pytest.raises(CaseFileError, match="not saved: .*case.json was changed") as caught:
            write(loaded.case, case.with_name("resaved.fcase"))
        assert "Traceback" not in str(caught.value)
    assert not case.with_name("resaved.fcase").exists()


def _old_unsealed(case: Path, out: str) -> None:
    info = _info_json(out)
    assert info["tampered"] is False and info["audit_chain"]["status"] == "verified (5 records)"
    assert info["audit_chain"]["content"]["status"] == (
        "content not sealed (written by an older version)"
    )
    assert info["audit_chain"]["content"]["state"] == "unsealed"


def _deep_text(depth: int = 100_000) -> bytes:
    return b"[" * depth + b"]" * depth


CHANGED = "case.json was changed outside the workbench after the last recorded save at"
BOMB = ("zip bomb", "more than 200 to 1")

FAULTS: dict[str, Fault] = {
    # ---- row 3: hand edits and duplicate members
    "row3-case-json-glabella-moved-10mm": Fault(
        lambda p: _edit_doc(p, _move_glabella),
        ("case", "info", "{case}"),
        2,
        ("case.json", CHANGED, "refusing to open"),
    ),
    "row3-case-json-examiner-renamed": Fault(
        lambda p: _edit_doc(p, _rename_examiner),
        ("case", "info", "{case}"),
        2,
        ("case.json", CHANGED),
    ),
    "row3-case-json-edited-reported-and-never-resealed": Fault(
        lambda p: _edit_doc(p, _move_glabella),
        ("case", "info", "{case}", "--allow-tampered"),
        0,
        ('"tampered": true', CHANGED),
        stream="out",
        then=_reported_edit,
    ),
    "row3-case-json-edited-snap-refuses-to-save": Fault(
        lambda p: _edit_doc(p, _rename_examiner),
        ("landmarks", "snap", "{case}", "--all"),
        2,
        ("case.json", CHANGED),
    ),
    "row3-case-json-edited-evidence-not-vouched-for": Fault(
        lambda p: _edit_doc(p, _rename_examiner),
        ("case", "evidence", "{case}", "skull.obj", "--out", "{tmp}/skull-out.obj"),
        2,
        (CHANGED, "evidence/skull.obj cannot be trusted"),
    ),
    "row3-second-case-json-member": Fault(
        lambda p: _add(p, "case.json", b'{"format_version": 3}'),
        ("case", "info", "{case}", "--allow-tampered"),
        2,
        ("two members named 'case.json'",),
    ),
    "row3-duplicate-evidence-member": Fault(
        lambda p: _add(p, "evidence/skull.obj", OBJ.replace(b"10", b"20")),
        ("case", "info", "{case}", "--allow-tampered"),
        2,
        ("two members named 'evidence/skull.obj'",),
    ),
    "row3-seal-removed-from-log": Fault(
        lambda p: _replace(
            p,
            "audit.jsonl",
            next(d for i, d in _members(p) if i.filename == "audit.jsonl").replace(
                b'"content_sha256"', b'"content_sha25X"'
            ),
        ),
        ("case", "info", "{case}"),
        2,
        ("audit.jsonl", "record 4", "edited"),
    ),
    "row3-old-case-without-seal-opens-unsealed": Fault(
        _as_previous_version,
        ("case", "info", "{case}"),
        0,
        ("content not sealed (written by an older version)",),
        stream="out",
        then=_old_unsealed,
    ),
    # ---- row 4: sizes, bombs, encryption, names, depth
    "row4-case-json-padded-with-spaces": Fault(
        lambda p: _deflated_run(p, "case.json", b"{", b" ", 64 * MIB),
        ("case", "info", "{case}", "--allow-tampered"),
        2,
        ("member case.json unpacks to 64.0 MiB", "more than the 16.0 MiB"),
    ),
    # evidence is sized by case.json (a mostly empty label volume deflates past any bomb
    # ratio and is real data): 8 MiB of zeros in place of a 67-byte file is refused by that,
    # after reading 68 bytes
    "row4-evidence-zip-bomb": Fault(
        lambda p: _deflated_run(p, "evidence/skull.obj", b"", b"\0", 8 * MIB),
        ("case", "info", "{case}"),
        2,
        ("evidence/skull.obj: larger than its recorded 67 bytes",),
    ),
    "row4-case-json-header-lies-about-size": Fault(
        _padded_with_lying_header,
        ("case", "info", "{case}", "--allow-tampered"),
        2,
        ("damaged", "Bad CRC-32"),
    ),
    "row4-encrypted-evidence-member": Fault(
        lambda p: _patch_headers(p, "evidence/skull.obj", _set_encrypted),
        ("case", "info", "{case}", "--allow-tampered"),
        2,
        ("member evidence/skull.obj is encrypted",),
    ),
    "row4-encrypted-case-json": Fault(
        lambda p: _patch_headers(p, "case.json", _set_encrypted),
        ("case", "info", "{case}"),
        2,
        ("member case.json is encrypted",),
    ),
    "row4-bzip2-case-json": Fault(
        lambda p: _replace(
            p,
            "case.json",
            next(d for i, d in _members(p) if i.filename == "case.json"),
            zipfile.ZIP_BZIP2,
        ),
        ("case", "info", "{case}"),
        2,
        ("member case.json is compressed with bzip2",),
    ),
    "row4-case-json-nested-100000-deep": Fault(
        lambda p: _replace(p, "case.json", _deep_text()),
        ("case", "info", "{case}", "--allow-tampered"),
        2,
        ("case.json member nests 100000 levels deep",),
    ),
    "row4-audit-line-nested-100000-deep": Fault(
        lambda p: _replace(
            p,
            "audit.jsonl",
            next(d for i, d in _members(p) if i.filename == "audit.jsonl") + _deep_text() + b"\n",
        ),
        ("case", "info", "{case}", "--allow-tampered"),
        2,
        ("audit.jsonl", "audit line 6 nests more than 64 levels deep"),
    ),
    "row4-member-name-with-dotdot": Fault(
        lambda p: _add(p, "evidence/../../escape.txt", b"x"),
        ("case", "info", "{case}"),
        2,
        ("member 'evidence/../../escape.txt' has a '..' part",),
    ),
    "row4-member-name-absolute": Fault(
        lambda p: _add(p, "/tmp/escape.txt", b"x"),
        ("case", "info", "{case}"),
        2,
        ("member '/tmp/escape.txt' has an absolute path",),
    ),
    "row4-ten-thousand-and-one-members": Fault(
        lambda p: _write(
            p, [*_members(p), *((_info(f"x/{i}", zipfile.ZIP_STORED), b"") for i in range(10_001))]
        ),
        ("case", "info", "{case}"),
        2,
        ("lists 10006 members", "at most 10000"),
    ),
    "row4-animate-track-nested-100000-deep": Fault(
        lambda p: p.with_name("track.json").write_bytes(_deep_text()),
        ("animate", "reference:male", "--track", "{tmp}/track.json", "--out", "{tmp}/clip.glb"),
        2,
        ("track.json", "track file nests 100000 levels deep"),
    ),
    "row4-animate-track-padded": Fault(
        lambda p: p.with_name("track.json").write_bytes(b'{"keys": []' + b" " * (40 * MIB) + b"}"),
        ("animate", "reference:male", "--track", "{tmp}/track.json", "--out", "{tmp}/clip.glb"),
        2,
        ("track.json", "the track file is 41.9 MB, more than the 34 MB"),
    ),
}


def _sha(folder: Path) -> dict[str, str]:
    return {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.iterdir())
        if p.is_file()
    }


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        status = main(argv)
    except SystemExit as exit_:  # argparse
        status = exit_.code if isinstance(exit_.code, int) else 2
    captured = capsys.readouterr()
    return status, captured.out, captured.err


@pytest.mark.parametrize(
    "fault_id",
    [pytest.param(fault_id, id=fault_id) for fault_id in FAULTS],
)
def test_fault(fault_id: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fault = FAULTS[fault_id]
    case = _case(tmp_path)
    fault.make(case)
    before = _sha(tmp_path)
    argv = [a.format(case=case, tmp=tmp_path) for a in fault.argv]
    status, out, err = _run(argv, capsys)
    said = out if fault.stream == "out" else err
    for leak in LEAKS:
        assert leak not in out + err, (leak, err[-2000:])
    assert status == fault.status, err[-2000:]
    named = argv[3] if argv[0] == "animate" else str(case)
    if fault.stream == "err":
        assert named in err, err
    for words in fault.says:
        assert words in said, (words, said[-2000:])
    assert _sha(tmp_path) == before  # nothing read was changed, nothing was written
    if fault.then is not None:
        fault.then(case, out)


def test_a_mostly_empty_evidence_member_is_not_a_zip_bomb(tmp_path: Path) -> None:
    """A label volume or mask of mostly zeros deflates beyond 200:1 and is real evidence: the
    case's arrays and evidence are sized by case.json, not judged by their ratio; any other
    member still is."""
    import zipfile

    from workbench.io.case_file import member_limit, sized_in_case
    from workbench.io.zip_limits import ZipLimitError, check_members, read_member

    path = tmp_path / "c.zip"
    zeros = bytes(8 * 1024 * 1024)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("evidence/mask.nii", zeros)
        z.writestr("arrays/ab.npy", zeros)
    with zipfile.ZipFile(path) as z:
        members = check_members(z, path, member_limit, ratio_exempt=sized_in_case)
        info = members["evidence/mask.nii"]
        assert info.file_size > 200 * info.compress_size
        assert read_member(z, info, path, len(zeros), ratio=False) == zeros
        with pytest.raises(ZipLimitError, match="zip bomb"):
            check_members(z, path, member_limit)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("notes/padding.txt", zeros)
    with zipfile.ZipFile(path) as z, pytest.raises(ZipLimitError, match="zip bomb"):
        check_members(z, path, member_limit, ratio_exempt=sized_in_case)
