"""The .fcase case file: round trip, integrity, atomic saves, audit log, migrations."""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import struct
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.commands.case_edits import AddEvidence, SetExaminer, SetParameter, SetSpecimen
from workbench.commands.landmarks import MoveLandmark, PlaceLandmark, SetLandmarkStatus
from workbench.commands.reconstruction_setup import (
    SetDepthOverride,
    SetDowelSettings,
    SetGuides,
    SetOrientation,
)
from workbench.commands.stack import CommandStack
from workbench.core.errors import WorkbenchError
from workbench.core.mesh import Mesh
from workbench.io import case_file
from workbench.io.case_file import CaseFileError, evidence_bytes, load_case, save_case
from workbench.io.migrations import MigrationError, migrate
from workbench.model.case import Case
from workbench.model.evidence import EvidenceFile
from workbench.model.reconstruction_setup import DowelSettings, GuideList, Orientation
from workbench.model.state import npy_bytes


def read_obj(path: Path) -> Mesh:
    """Tiny OBJ reader for the test (``v`` and triangular ``f`` lines only)."""
    vertices, faces = [], []
    with open(path, encoding="utf-8") as stream:
        for line in stream:
            if line.startswith("v "):
                vertices.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("f "):
                faces.append([int(t.split("/")[0]) - 1 for t in line.split()[1:4]])
    return Mesh(np.asarray(vertices), np.asarray(faces))


@pytest.fixture(scope="module")
def skull_mesh(skull_obj: Path) -> Mesh:
    return read_obj(skull_obj)


@pytest.fixture
def session(skull_obj: Path, skull_mesh: Mesh) -> tuple[Case, CommandStack]:
    """A case with the real skull as evidence and specimen, landmarks and parameters."""
    case = Case()
    stack = CommandStack(case)
    stack.push(SetExaminer("A. Examiner"))
    stack.push(
        AddEvidence(
            EvidenceFile.from_path(skull_obj, "skull_mesh", units_note="unitless as distributed")
        )
    )
    transform = np.eye(4)
    transform[:3, :3] *= 10.0
    stack.push(SetSpecimen(skull_mesh, "unitless", transform))
    stack.push(PlaceLandmark("skull", "n", skull_mesh.vertices[10]))
    stack.push(PlaceLandmark("skull", "g", skull_mesh.vertices[20]))
    stack.push(SetLandmarkStatus("skull", "pg", "absent"))
    stack.push(PlaceLandmark("skin", "prn", [0.1, 0.2, 0.3]))
    stack.push(
        SetDowelSettings(table="stephan_2013", sex="female", build=-1.5, excluded=("ecm2s_l",))
    )
    stack.push(SetDepthOverride("g", 6.5))
    stack.push(SetOrientation(((0, 0, 1), (0, 1, 0))))
    stack.push(SetGuides([{"id": "nose_tip", "value": [20.0, 95.5], "source": "user"}]))
    stack.push(SetParameter("nose_notes", {"nose": {"projection_mm": 17.5}}))
    stack.push(SetParameter("look_alike", {"@array": "not an array ref", "dtype": None}))
    return case, stack


@pytest.fixture
def saved(session: tuple[Case, CommandStack], tmp_path: Path) -> Path:
    case, stack = session
    return save_case(case, tmp_path / "case.fcase", stack)


def rewrite_member(path: Path, name: str, change: Callable[[bytes], bytes]) -> None:
    """Rewrite the zip with one member changed (a deliberate tamper, CRC kept valid)."""
    with zipfile.ZipFile(path) as source:
        items = [(info, source.read(info.filename)) for info in source.infolist()]
    with zipfile.ZipFile(path, "w") as target:
        for info, data in items:
            target.writestr(info, change(data) if info.filename == name else data)


def drop_member(path: Path, name: str) -> None:
    with zipfile.ZipFile(path) as source:
        items = [(i, source.read(i.filename)) for i in source.infolist() if i.filename != name]
    with zipfile.ZipFile(path, "w") as target:
        for info, data in items:
            target.writestr(info, data)


def flip_byte(data: bytes, at: int = 100) -> bytes:
    return data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1 :]


def array_members(path: Path) -> list[str]:
    with zipfile.ZipFile(path) as archive:
        return [n for n in archive.namelist() if n.startswith("arrays/")]


# ---------------------------------------------------------------- round trip
def test_round_trip_with_real_skull(session, saved: Path, skull_obj: Path) -> None:
    case, stack = session
    assert not stack.is_dirty
    assert case.source_path == saved
    loaded = load_case(saved)
    assert loaded.case.equals(case)
    assert loaded.case.specimen.mesh.equals(case.specimen.mesh)
    assert loaded.case.specimen.mesh.n_faces == case.specimen.mesh.n_faces > 50_000
    assert not loaded.tampered
    assert set(loaded.evidence_status.values()) == {"ok"}
    assert "evidence/skull.obj" in loaded.evidence_status
    original = skull_obj.read_bytes()
    stored = evidence_bytes(saved, "skull.obj")
    assert stored == original
    assert hashlib.sha256(stored).hexdigest() == case.evidence[0].sha256
    assert [r["operation"] for r in loaded.audit_records][-1] == "Save case"
    assert loaded.case.retained_evidence == case.retained_evidence


def test_zip_layout(saved: Path, skull_obj: Path) -> None:
    with zipfile.ZipFile(saved) as archive:
        names = archive.namelist()
        doc = json.loads(archive.read("case.json"))
        evidence_info = archive.getinfo("evidence/skull.obj")
        assert archive.read("evidence/skull.obj") == skull_obj.read_bytes()
        for name in array_members(saved):
            data = archive.read(name)
            assert name == f"arrays/{hashlib.sha256(data).hexdigest()}.npy"
            np.load(io.BytesIO(data), allow_pickle=False)
    assert names[0] == "case.json"
    assert "audit.jsonl" in names
    assert doc["@schema"] == "case-schema-v3"
    assert doc["format_version"] == 3
    assert doc["dowels"] == {
        "table": "stephan_2013",
        "sex": "female",
        "build": -1.5,
        "overrides": {"g": 6.5},
        "excluded": ["ecm2s_l"],
        "tissue_model": "table",
        "region_factors": {},
        "jaw": "occlusion",
    }
    assert doc["orientation"] == {"anterior": [0, 0, 1], "superior": [0, 1, 0], "left": None}
    assert doc["guides"][0]["id"] == "nose_tip"
    assert doc["software"].endswith(workbench.__version__)
    assert evidence_info.compress_type == zipfile.ZIP_STORED
    assert len(array_members(saved)) == 2
    assert doc["specimen"]["mesh"]["faces"]["dtype"] == "int64"
    assert doc["landmarks"]["skull"]["landmarks"][2]["position"] is None


def test_load_never_touches_the_file(saved: Path) -> None:
    before = (saved.read_bytes(), saved.stat().st_mtime_ns)
    load_case(saved)
    evidence_bytes(saved, "skull.obj")
    assert (saved.read_bytes(), saved.stat().st_mtime_ns) == before


# ---------------------------------------------------------------- tampering
def test_tampered_evidence_is_refused_then_flagged(saved: Path) -> None:
    rewrite_member(saved, "evidence/skull.obj", flip_byte)
    tampered = saved.read_bytes()
    with pytest.raises(CaseFileError, match=r"evidence/skull\.obj: sha256 mismatch") as info:
        load_case(saved)
    assert str(saved) in str(info.value)
    assert isinstance(info.value, WorkbenchError)
    loaded = load_case(saved, allow_tampered=True)
    assert loaded.tampered
    assert loaded.evidence_status["evidence/skull.obj"].startswith("sha256 mismatch")
    assert all(s == "ok" for k, s in loaded.evidence_status.items() if k.startswith("arrays/"))
    with pytest.raises(CaseFileError, match="does not match"):
        evidence_bytes(saved, "skull.obj")
    assert evidence_bytes(saved, "skull.obj", allow_tampered=True) != b""
    assert saved.read_bytes() == tampered


def test_tampered_array_is_refused_then_flagged(saved: Path) -> None:
    member = array_members(saved)[0]
    rewrite_member(saved, member, lambda data: flip_byte(data, len(data) - 3))
    with pytest.raises(CaseFileError, match="integrity check failed"):
        load_case(saved)
    loaded = load_case(saved, allow_tampered=True)
    assert loaded.evidence_status[member].startswith("sha256 mismatch")
    assert loaded.evidence_status["evidence/skull.obj"] == "ok"


def test_byte_flipped_in_place_is_refused(saved: Path) -> None:
    with zipfile.ZipFile(saved) as archive:
        offset = archive.getinfo("evidence/skull.obj").header_offset
    raw = bytearray(saved.read_bytes())
    name_len, extra_len = struct.unpack("<HH", raw[offset + 26 : offset + 30])
    raw[offset + 30 + name_len + extra_len + 1000] ^= 0x01
    saved.write_bytes(bytes(raw))
    with pytest.raises(CaseFileError, match=r"evidence/skull\.obj"):
        load_case(saved)
    loaded = load_case(saved, allow_tampered=True)
    assert loaded.evidence_status["evidence/skull.obj"] != "ok"


# ---------------------------------------------------------------- corrupt files
def test_truncated_file(saved: Path) -> None:
    data = saved.read_bytes()
    saved.write_bytes(data[: len(data) // 2])
    cut = saved.read_bytes()
    with pytest.raises(CaseFileError, match="damaged or truncated") as info:
        load_case(saved)
    assert str(saved) in str(info.value)
    assert saved.read_bytes() == cut


def _set_doc(path: Path, edit: Callable[[dict], object]) -> None:
    def change(data: bytes) -> bytes:
        doc = json.loads(data)
        edit(doc)
        return json.dumps(doc).encode()

    rewrite_member(path, "case.json", change)


def _pickled() -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.array([{"x": 1}], dtype=object), allow_pickle=True)
    return buffer.getvalue()


CORRUPTIONS: dict[str, tuple[Callable[[Path], None], str]] = {
    "not a zip": (lambda p: p.write_text("hello"), "damaged or truncated"),
    "invalid json": (lambda p: rewrite_member(p, "case.json", lambda d: d[:-5]), "not valid JSON"),
    "nan in json": (
        lambda p: rewrite_member(
            p, "case.json", lambda d: d.replace(b'"confidence": 1.0', b'"confidence": NaN', 1)
        ),
        "not valid JSON",
    ),
    "schema violation": (
        lambda p: _set_doc(
            p, lambda d: d["landmarks"]["skull"]["landmarks"][0].update(status="lost")
        ),
        r"landmarks.*skull",
    ),
    "class name in file": (
        lambda p: _set_doc(p, lambda d: d["specimen"].update({"@class": "os.system"})),
        "case-schema-v3",
    ),
    "negative dowel depth": (
        lambda p: _set_doc(p, lambda d: d["dowels"]["overrides"].update(g=-2.0)),
        r"dowels.*overrides",
    ),
    "unknown build": (
        lambda p: _set_doc(p, lambda d: d["dowels"].update(build="slim")),
        r"dowels.*build",
    ),
    "parallel orientation": (
        lambda p: _set_doc(p, lambda d: d["orientation"].update(superior=[0, 0, 2])),
        "parallel",
    ),
    "missing array": (lambda p: drop_member(p, array_members(p)[0]), "missing from the case file"),
    "missing case.json": (lambda p: drop_member(p, "case.json"), "case.json is missing"),
    "newer format": (lambda p: _set_doc(p, lambda d: d.update(format_version=7)), "newer version"),
    "pickled array": (
        lambda p: rewrite_member(p, array_members(p)[0], lambda d: _pickled()),
        "not a readable array",
    ),
    "damaged audit": (
        lambda p: rewrite_member(p, "audit.jsonl", lambda d: d + b"{x\n"),
        "audit log is damaged",
    ),
    "array shape": (
        lambda p: _set_doc(p, lambda d: d["specimen"]["mesh"]["faces"].update(shape=[1, 3])),
        "expects int64",
    ),
}


@pytest.mark.parametrize("name", list(CORRUPTIONS))
def test_corrupt_files_give_case_file_error(saved: Path, name: str) -> None:
    corrupt, message = CORRUPTIONS[name]
    corrupt(saved)
    before = saved.read_bytes()
    with pytest.raises(CaseFileError, match=message) as info:
        load_case(saved, allow_tampered=True)
    assert str(saved) in str(info.value)
    assert saved.read_bytes() == before


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(CaseFileError, match="no such case file"):
        load_case(tmp_path / "nope.fcase")


# ---------------------------------------------------------------- atomic saves
def test_failing_save_leaves_previous_file_intact(session, saved: Path, monkeypatch) -> None:
    case, stack = session
    before = saved.read_bytes()
    stack.push(MoveLandmark("skull", "n", [1, 2, 3]))
    modified, pending = case.meta.modified, case.audit.pending
    real = zipfile.ZipFile.writestr

    def failing(self, info, data, *args, **kwargs):
        name = info.filename if isinstance(info, zipfile.ZipInfo) else info
        if name == "audit.jsonl":  # after case.json, arrays and evidence
            raise RuntimeError("disk on fire")
        return real(self, info, data, *args, **kwargs)

    monkeypatch.setattr(zipfile.ZipFile, "writestr", failing)
    with pytest.raises(RuntimeError, match="disk on fire"):
        save_case(case, saved, stack)
    monkeypatch.undo()
    assert saved.read_bytes() == before
    assert sorted(p.name for p in saved.parent.iterdir()) == ["case.fcase"]
    assert stack.is_dirty
    assert case.meta.modified == modified
    assert case.audit.pending == pending
    assert load_case(saved).case.landmarks["skull"]["n"].position.tolist() != [1, 2, 3]


def test_os_error_during_save_is_a_case_file_error(session, saved: Path, monkeypatch) -> None:
    case, stack = session
    before = saved.read_bytes()

    def no_replace(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(case_file.os, "replace", no_replace)
    with pytest.raises(CaseFileError, match="could not save"):
        save_case(case, saved, stack)
    monkeypatch.undo()
    assert saved.read_bytes() == before
    assert sorted(p.name for p in saved.parent.iterdir()) == ["case.fcase"]


# ---------------------------------------------------------------- audit log
def test_audit_log_is_append_only_across_saves(session, saved: Path, tmp_path: Path) -> None:
    case, stack = session
    with zipfile.ZipFile(saved) as archive:
        first = archive.read("audit.jsonl")
    stack.push(MoveLandmark("skull", "n", [1, 2, 3]))
    stack.undo()
    save_case(case, saved, stack)
    with zipfile.ZipFile(saved) as archive:
        second = archive.read("audit.jsonl")
    assert second.startswith(first)
    assert len(second) > len(first)
    tail = [json.loads(line) for line in second[len(first) :].splitlines()]
    assert [r["action"] for r in tail] == ["do", "undo", "save"]
    # a reopened case saved under a new name keeps the whole log as a prefix
    reopened = load_case(saved).case
    CommandStack(reopened).push(SetParameter("build", "slim"))
    copy = save_case(reopened, tmp_path / "copy.fcase")
    with zipfile.ZipFile(copy) as archive:
        third = archive.read("audit.jsonl")
    assert third.startswith(second)
    assert evidence_bytes(copy, "skull.obj") == evidence_bytes(saved, "skull.obj")


def test_save_refuses_a_log_written_by_another_session(saved: Path) -> None:
    first, second = load_case(saved).case, load_case(saved).case
    CommandStack(first).push(SetParameter("build", "slim"))
    save_case(first, saved)
    kept = saved.read_bytes()
    CommandStack(second).push(SetParameter("build", "obese"))
    with pytest.raises(CaseFileError, match="another session"):
        save_case(second, saved)
    assert saved.read_bytes() == kept


# ---------------------------------------------------------------- evidence storage
def test_evidence_bytes_outlive_undo_and_the_original(tmp_path: Path) -> None:
    original = tmp_path / "photo.jpg"
    original.write_bytes(os.urandom(5000))
    payload = original.read_bytes()
    case = Case()
    stack = CommandStack(case)
    stack.push(AddEvidence(EvidenceFile.from_path(original, "photograph")))
    path = save_case(case, tmp_path / "c.fcase", stack)
    stack.undo()
    original.unlink()
    save_case(case, path, stack)
    loaded = load_case(path)
    assert loaded.case.evidence == ()
    assert "photo.jpg" in loaded.case.retained_evidence
    assert evidence_bytes(path, "photo.jpg") == payload
    records = [r for r in loaded.audit_records if r["command"] == "AddEvidence"]
    assert [r["action"] for r in records] == ["do", "undo"]


def test_save_refuses_evidence_it_cannot_find(tmp_path: Path) -> None:
    original = tmp_path / "scan.ply"
    original.write_bytes(b"ply\n" * 100)
    case = Case()
    CommandStack(case).push(AddEvidence(EvidenceFile.from_path(original, "skull_mesh")))
    original.write_bytes(b"changed")
    with pytest.raises(CaseFileError, match=r"no copy of evidence 'scan\.ply'"):
        save_case(case, tmp_path / "c.fcase")
    original.unlink()
    with pytest.raises(CaseFileError, match="no copy"):
        save_case(case, tmp_path / "c.fcase")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# ---------------------------------------------------------------- migrations
V0_CASE_ID = "0b7e4c1e-5a37-4c2b-9a53-3f8f0f1f6d2e"


@pytest.fixture
def v0_file(tmp_path: Path) -> Path:
    """A format-0 case file as the development builds wrote it."""
    vertices = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
    evidence = b"solid skull\nendsolid skull\n"
    arrays = {}
    refs = {}
    for key, array in (("vertices", vertices), ("faces", faces)):
        data = npy_bytes(array)
        sha = hashlib.sha256(data).hexdigest()
        arrays[f"arrays/{sha}.npy"] = data
        refs[key] = {"sha256": sha, "dtype": array.dtype.name, "shape": list(array.shape)}
    doc = {
        "format_version": 0,
        "software": "workbench 0.0.9",
        "case_id": V0_CASE_ID,
        "examiner": "Old Examiner",
        "created": "2024-03-01T10:00:00+00:00",
        "skull": {**refs, "units": "mm"},
        "head_transform": np.eye(4).tolist(),
        "landmarks": {"skull": {"n": [0.0, 5.0, 9.0]}, "skin": {"prn": [1.0, 2.0, 3.0]}},
        "evidence": [
            {
                "file": "skull.stl",
                "sha256": hashlib.sha256(evidence).hexdigest(),
                "bytes": len(evidence),
                "kind": "skull_mesh",
                "source": "/cases/skull.stl",
            }
        ],
        "settings": {"depth_table": "old_table"},
    }
    path = tmp_path / "old.fcase"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("case.json", json.dumps(doc))
        for name, data in arrays.items():
            archive.writestr(name, data)
        archive.writestr("evidence/skull.stl", evidence)
    return path


def test_v0_file_is_migrated(v0_file: Path, tmp_path: Path) -> None:
    loaded = load_case(v0_file)
    case = loaded.case
    assert case.meta.case_id == V0_CASE_ID
    assert case.meta.examiner == "Old Examiner"
    assert case.meta.software_version == "0.0.9"
    assert case.specimen.mesh.n_faces == 4
    assert np.array_equal(case.specimen.input_to_head, np.eye(4))
    assert case.landmarks["skull"]["n"].position.tolist() == [0, 5, 9]
    assert case.landmarks["skin"]["prn"].status == "placed"
    assert [e.name for e in case.evidence] == ["skull.stl"]
    assert case.dowels.table == "old_table"
    assert "depth_table" not in case.parameters
    assert loaded.audit_records == ()
    assert not loaded.tampered
    # saving writes the current format and keeps the evidence bytes
    new = save_case(case, tmp_path / "new.fcase")
    with zipfile.ZipFile(new) as archive:
        assert json.loads(archive.read("case.json"))["format_version"] == 3
    assert load_case(new).case.equals(case)
    assert evidence_bytes(new, "skull.stl") == evidence_bytes(v0_file, "skull.stl")


def test_migrate_is_pure_and_ordered(v0_file: Path) -> None:
    with zipfile.ZipFile(v0_file) as archive:
        doc = json.loads(archive.read("case.json"))
    snapshot = json.dumps(doc, sort_keys=True)
    new, applied = migrate(doc)
    assert applied == [0, 1, 2]
    assert new["format_version"] == 3
    assert json.dumps(doc, sort_keys=True) == snapshot
    assert migrate(new) == (new, [])
    steps = {
        0: lambda d: {**d, "format_version": 1, "seen": [0]},
        1: lambda d: {**d, "format_version": 2, "seen": [*d["seen"], 1]},
        2: lambda d: {**d, "format_version": 3, "seen": [*d["seen"], 2]},
    }
    assert migrate({"format_version": 0}, steps)[0]["seen"] == [0, 1, 2]
    with pytest.raises(MigrationError, match="no migration from format_version -1"):
        migrate({"format_version": -1})
    with pytest.raises(MigrationError, match="newer"):
        migrate({"format_version": 4})
    with pytest.raises(MigrationError, match="integer"):
        migrate({"format_version": "1"})
    with pytest.raises(MigrationError, match="cannot upgrade format_version 0"):
        migrate({"format_version": 0})


# ---------------------------------------------------------------- schema location
def test_schema_found_in_wheel_data_first(tmp_path: Path, monkeypatch) -> None:
    source_tree = Path(workbench.__file__).parents[1] / "data_tables" / "schemas"
    assert case_file.schema_dir() == source_tree
    package = tmp_path / "site" / "workbench"
    wheel_schemas = package / "_data" / "data_tables" / "schemas"
    wheel_schemas.mkdir(parents=True)
    shutil.copy(case_file.schema_dir() / "case.schema.json", wheel_schemas)
    monkeypatch.setattr(workbench, "__file__", str(package / "__init__.py"))
    assert case_file.schema_dir() == wheel_schemas


# ---------------------------------------------------------------- format 1 -> 2
V1_GUIDE = {
    "id": "nose_tip",
    "label": "Nose tip",
    "kind": "point",
    "view": "lateral",
    "value": [-20.0, 95.0],
    "affects": ["prn"],
    "rule_id": "kaehler_nose_tip",
    "citation": "Kähler 2003",
    "source": "user",
    "enabled": True,
    "derivation": "",
}


def _v1_file(v0_file: Path, path: Path, parameters: dict) -> Path:
    """A format-1 case file as the 0.1 software wrote it, with ``parameters``."""
    from workbench.io.migrations import v0_to_v1

    with zipfile.ZipFile(v0_file) as source:
        members = {n: source.read(n) for n in source.namelist()}
    doc = v0_to_v1(json.loads(members.pop("case.json")))
    doc["parameters"] = parameters
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("case.json", json.dumps(doc))
        for name, data in members.items():
            archive.writestr(name, data)
    return path


def test_v1_parameters_become_typed_parts(v0_file: Path, tmp_path: Path) -> None:
    old = {
        "depth_table": "ttable_2023",
        "sex": "female",
        "build": "1.5",
        "depth_overrides": {"g": 6.5, "n": 7},
        "excluded_landmarks": ["ecm2s_r", "ecm2s_l"],
        "guides": [V1_GUIDE],
        "orientation": {"anterior": [0, -2, 0], "superior": [0, 0, -1]},
        "template_hash": "abc123",
        "look_alike": {"@array": "x"},
    }
    path = _v1_file(v0_file, tmp_path / "v1.fcase", old)
    with zipfile.ZipFile(path) as archive:
        doc = json.loads(archive.read("case.json"))
    assert doc["format_version"] == 1 and doc["@schema"] == "case-schema-v1"
    assert migrate(doc)[1] == [1, 2]
    loaded = load_case(path)
    case = loaded.case
    assert case.dowels == DowelSettings(
        table="ttable_2023",
        sex="female",
        build=1.5,
        overrides={"g": 6.5, "n": 7.0},
        excluded=("ecm2s_l", "ecm2s_r"),
    )
    assert case.orientation == Orientation((0, -1, 0), (0, 0, -1))
    assert case.guides == GuideList((V1_GUIDE,))
    from workbench.services.guides.classic import guides_from_json

    assert guides_from_json(case.guides.to_state())[0].value == (-20.0, 95.0)
    # parameters that are not settings stay as they were
    assert thaw(case.parameters) == {"template_hash": "abc123", "look_alike": {"@array": "x"}}
    assert not loaded.tampered and case.meta.case_id == V0_CASE_ID
    # saved again: format 2, same case, evidence bytes untouched
    new = save_case(case, tmp_path / "v2.fcase")
    with zipfile.ZipFile(new) as archive:
        assert json.loads(archive.read("case.json"))["format_version"] == 3
    again = load_case(new).case
    assert again.equals(case) and again.dowels == case.dowels
    assert evidence_bytes(new, "skull.stl") == evidence_bytes(path, "skull.stl")


def test_v1_values_that_are_not_settings_stay_parameters(v0_file: Path, tmp_path: Path) -> None:
    old = {
        "build": "slim",
        "sex": "unknown",
        "guides": {"nose": {"projection_mm": 17.5}},
        "orientation": {},
        "depth_overrides": {"g": -1},
        "excluded_landmarks": "g",
        "depth_table": "stephan_2013",
    }
    case = load_case(_v1_file(v0_file, tmp_path / "odd.fcase", old)).case
    assert case.dowels == DowelSettings(table="stephan_2013")
    assert case.orientation is None and case.guides is None
    assert thaw(case.parameters) == {
        k: v for k, v in old.items() if k not in ("orientation", "depth_table")
    }


def thaw(value: object) -> object:
    from workbench.model.state import thaw_json

    return thaw_json(value)
