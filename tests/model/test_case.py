"""The Case document: parts, state round trips, events, immutability."""

from __future__ import annotations

import io
import json
import math
import uuid

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import workbench
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model import case as case_module
from workbench.model.audit import AuditLog, encode_record, make_record, parse_records
from workbench.model.case import PARTS, Case, EvidenceConflictError
from workbench.model.evidence import EvidenceFile, sha256_file
from workbench.model.landmarks import landmark_set_from_state, landmark_set_to_state
from workbench.model.meta import CaseMeta
from workbench.model.reconstruction_setup import DowelSettings, GuideList, Orientation
from workbench.model.specimen import Specimen
from workbench.model.state import (
    freeze_json,
    join_arrays,
    split_arrays,
    states_equal,
    thaw_json,
)

SHA = "ab" * 32


def tetra() -> Mesh:
    v = [[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]]
    return Mesh(v, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def full_case() -> Case:
    skull = LandmarkSet(
        "skull",
        (
            Landmark("n", [1.5, 2.25, -3.0]),
            Landmark("zy_l", [60.0, 1.0, 2.0], "suggested", 0.4, "auto"),
            Landmark("pg", [np.nan] * 3, "absent", description="mandible missing"),
        ),
    )
    skin = LandmarkSet.from_points("skin", {"prn": (0.1, 0.2, 0.3)})
    transform = np.eye(4)
    transform[:3, 3] = [1.0, -2.0, 0.5]
    return Case(
        meta=CaseMeta.new("A. Examiner", "notes with ünïcode"),
        evidence=(EvidenceFile("skull.obj", SHA, 12, "skull_mesh", "/x/skull.obj", "unitless"),),
        specimen=Specimen(tetra(), "mm", transform),
        landmarks={"skull": skull, "skin": skin},
        dowels=DowelSettings(
            table="stephan_2013",
            sex="female",
            build=-1.0,
            overrides={"g": 6.5},
            excluded=("ecm2s_l",),
            tissue_model="reference",
            region_factors={"nose": 1.2},
        ),
        orientation=Orientation((0.0, -1.0, 0.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0)),
        guides=GuideList(({"id": "nose_tip", "value": [-20.0, 95.0], "source": "user"},)),
        parameters={"template_id": "male-v1", "notes": {"nose": [1, 2.5, None, True]}},
    )


def json_round_trip(case: Case) -> Case:
    """to_state -> JSON text + arrays -> from_state, part by part as the case file does.

    Only parts flagged ``has_arrays`` hold array references, so a user
    parameter that happens to contain an ``"@array"`` key stays plain JSON.
    """
    doc, blobs = {}, {}
    for name, state in case.to_state().items():
        if PARTS[name].has_arrays:
            state, part_blobs = split_arrays(state)
            blobs.update(part_blobs)
        doc[name] = state
    doc = json.loads(json.dumps(doc, allow_nan=False))
    arrays = {sha: np.load(io.BytesIO(data), allow_pickle=False) for sha, data in blobs.items()}
    state = {
        name: join_arrays(part, lambda ref: arrays[ref["@array"]])
        if PARTS[name].has_arrays
        else part
        for name, part in doc.items()
    }
    return Case.from_state(state)


# ---------------------------------------------------------------- per-part round trips
@pytest.mark.parametrize("name", list(PARTS))
def test_every_part_round_trips(name: str) -> None:
    case = full_case()
    codec = PARTS[name]
    value = case.part(name)
    again = codec.coerce(codec.from_state(codec.to_state(value)))
    assert states_equal(codec.to_state(again), codec.to_state(value))


def test_whole_case_round_trips_through_state_and_json() -> None:
    case = full_case()
    assert Case.from_state(case.to_state()).equals(case)
    again = json_round_trip(case)
    assert again.equals(case)
    assert again.landmarks["skull"].equals(case.landmarks["skull"])
    assert again.specimen.equals(case.specimen)
    assert again.meta == case.meta


def test_default_case_is_empty_and_round_trips() -> None:
    case = Case()
    assert case.evidence == ()
    assert case.specimen.mesh is None
    assert case.specimen.input_to_head is None
    assert set(case.landmarks) == {"skin", "skull"}
    assert all(len(s) == 0 for s in case.landmarks.values())
    assert dict(case.parameters) == {}
    assert case.dowels == DowelSettings() and case.dowels.table == "ttable_2023"
    assert case.orientation is None and case.guides is None
    assert json_round_trip(case).equals(case)


def test_meta_new_has_uuid4_times_and_version() -> None:
    meta = CaseMeta.new("X")
    assert uuid.UUID(meta.case_id).version == 4
    assert meta.created == meta.modified
    assert "T" in meta.created
    assert meta.software_version == workbench.__version__
    assert CaseMeta.from_state(meta.to_state()) == meta
    with pytest.raises(ValueError, match="UUID"):
        CaseMeta("not-a-uuid")
    with pytest.raises(ValueError, match="unknown"):
        CaseMeta.from_state({**meta.to_state(), "colour": "red"})


def test_equals_sees_small_differences() -> None:
    a = full_case()
    b = Case.from_state(a.to_state())
    moved = a.landmarks["skull"]["n"].position + np.array([0.0, 0.0, 1e-12])
    b.set_landmark_set(b.landmarks["skull"].with_landmark(Landmark("n", moved)))
    assert not a.equals(b)
    c = Case.from_state(a.to_state())
    c.replace("parameters", {**thaw_json(c.parameters), "depth_table": "other"})
    assert not a.equals(c)
    e = Case.from_state(a.to_state())
    e.replace("dowels", e.dowels.with_override("g", 6.6))
    assert not a.equals(e)
    f = Case.from_state(a.to_state())
    f.replace("orientation", None)
    assert not a.equals(f)
    d = Case.from_state(a.to_state())
    d.replace("specimen", Specimen(tetra(), "cm", a.specimen.input_to_head))
    assert not a.equals(d)


# ---------------------------------------------------------------- replace and events
def test_replace_emits_changed_with_part_name() -> None:
    case = Case()
    seen: list[str] = []
    case.events.changed.connect(seen.append)
    case.replace("parameters", {"build": "average"})
    case.set_landmark_set(LandmarkSet.from_points("skull", {"n": (0, 0, 0)}))
    case.replace("specimen", Specimen(tetra()))
    case.replace("dowels", DowelSettings(sex="female"))
    case.replace("orientation", Orientation((0, 0, 1), (0, 1, 0)))
    case.replace("guides", GuideList())
    assert seen == ["parameters", "landmarks", "specimen", "dowels", "orientation", "guides"]


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("meta", "not meta"),
        ("specimen", tetra()),
        ("evidence", [EvidenceFile("a", SHA, 1, "other")] * 2),
        ("landmarks", {"skull": LandmarkSet("skin")}),
        ("landmarks", {"bone": LandmarkSet("skull")}),
        ("parameters", {"x": float("nan")}),
        ("parameters", {"x": object()}),
        ("parameters", {1: "x"}),
        ("dowels", None),
        ("dowels", {"table": "ttable_2023"}),
        ("orientation", ((0, 0, 1), (0, 1, 0))),
        ("guides", [{"id": "a", "value": [1.0]}]),
    ],
)
def test_invalid_replace_raises_and_changes_nothing(name: str, value: object) -> None:
    case = full_case()
    before = case.to_state()
    seen: list[str] = []
    case.events.changed.connect(seen.append)
    with pytest.raises((TypeError, ValueError)):
        case.replace(name, value)
    assert states_equal(case.to_state(), before)
    assert seen == []


def test_unknown_parts_are_refused() -> None:
    with pytest.raises(TypeError, match="unknown case parts"):
        Case(growth=())
    with pytest.raises(KeyError):
        Case().replace("growth", ())
    with pytest.raises(ValueError, match="unknown parts"):
        Case.from_state({**Case().to_state(), "growth": []})
    state = Case().to_state()
    del state["dowels"]
    with pytest.raises(ValueError, match="missing parts"):
        Case.from_state(state)


def test_parts_cannot_be_mutated_in_place() -> None:
    case = full_case()
    with pytest.raises(ValueError, match="read-only"):
        case.specimen.mesh.vertices[0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        case.specimen.input_to_head[0, 0] = 2.0
    with pytest.raises(TypeError):
        case.parameters["depth_table"] = "x"  # type: ignore[index]
    with pytest.raises(TypeError):
        case.parameters["notes"]["nose"][0] = 5  # type: ignore[index]
    with pytest.raises(TypeError):
        case.dowels.overrides["g"] = 1.0  # type: ignore[index]
    with pytest.raises(TypeError):
        case.guides.guides[0]["value"] = [1.0]  # type: ignore[index, union-attr]
    with pytest.raises(TypeError):
        case.landmarks["skin"] = LandmarkSet("skin")  # type: ignore[index]


def test_parameters_are_copied_on_replace() -> None:
    case = Case()
    value = {"guide": [1, 2]}
    case.replace("parameters", value)
    value["guide"].append(3)
    assert thaw_json(case.parameters) == {"guide": [1, 2]}


def test_head_mesh_applies_input_to_head() -> None:
    case = full_case()
    head = case.specimen.head_mesh
    assert np.allclose(head.vertices, case.specimen.mesh.vertices + np.array([1.0, -2.0, 0.5]))
    with pytest.raises(ValueError, match="affine"):
        Specimen(tetra(), "mm", np.ones((4, 4)))


# ---------------------------------------------------------------- evidence
def test_evidence_file_from_path_hashes(tmp_path) -> None:
    path = tmp_path / "scan.ply"
    path.write_bytes(b"ply\nformat ascii 1.0\n")
    item = EvidenceFile.from_path(path, "skull_mesh", units_note="mm")
    assert (item.sha256, item.size) == sha256_file(path)
    assert item.name == "scan.ply"
    assert item.original_path == str(path.resolve())
    assert EvidenceFile.from_state(item.to_state()) == item


@pytest.mark.parametrize("name", ["", ".", "..", "a/b", "..\\x", "bad\nname"])
def test_evidence_names_must_be_plain(name: str) -> None:
    with pytest.raises(ValueError, match="plain file name"):
        EvidenceFile(name, SHA, 1, "other")


def test_evidence_fields_are_checked() -> None:
    with pytest.raises(ValueError, match="sha256"):
        EvidenceFile("a", "ABC", 1, "other")
    with pytest.raises(ValueError, match="size"):
        EvidenceFile("a", SHA, -1, "other")
    with pytest.raises(ValueError, match="role"):
        EvidenceFile("a", SHA, 1, "Skull Mesh")


def test_retained_evidence_outlives_the_reference() -> None:
    item = EvidenceFile("a.obj", SHA, 3, "skull_mesh")
    case = Case(evidence=(item,))
    case.replace("evidence", ())
    assert case.evidence == ()
    assert case.retained_evidence == {"a.obj": item}
    other = EvidenceFile("a.obj", "cd" * 32, 3, "skull_mesh")
    with pytest.raises(EvidenceConflictError, match=r"a\.obj"):
        case.replace("evidence", (other,))
    assert case.evidence == ()
    assert case.unused_evidence_name("a.obj") == "a-2.obj"
    assert case.unused_evidence_name("b.obj") == "b.obj"


# ---------------------------------------------------------------- audit log
def test_audit_log_keeps_persisted_bytes_and_appends() -> None:
    first = encode_record(make_record("do", "Place", "X", {"p": [1.0, 2.0]}))
    log = AuditLog(first)
    assert len(log) == 1
    assert log.pending == ()
    log.append(make_record("undo", "Place", "X"))
    data = log.encode()
    assert data.startswith(first)
    assert len(parse_records(data)) == 2
    log.mark_persisted(data)
    assert log.pending == ()
    assert log.persisted_bytes == data
    with pytest.raises(ValueError, match="JSON compliant"):
        log.append({"x": float("nan")})
    with pytest.raises(ValueError, match="cut off"):
        parse_records(first[:-1])
    with pytest.raises(ValueError, match="line 2"):
        parse_records(first + b"{oops\n")


# ---------------------------------------------------------------- state helpers
def test_states_equal_is_exact() -> None:
    a = np.array([1.0, np.nan])
    assert states_equal({"a": a}, {"a": a.copy()})
    assert not states_equal(a, a.astype(np.float32))
    assert not states_equal([1], [1.0])
    assert states_equal(math.nan, math.nan)
    assert not states_equal({"a": 1}, {"b": 1})
    assert not states_equal([1, 2], [1, 2, 3])


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers()
    | st.text(max_size=5)
    | st.floats(allow_nan=False, allow_infinity=False),
    lambda children: (
        st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=4), children, max_size=3)
    ),
    max_leaves=10,
)


@settings(max_examples=60, deadline=None)
@given(
    st.dictionaries(
        st.sampled_from(["@array", "dtype", "k"]) | st.text(min_size=1, max_size=8),
        json_values,
        max_size=4,
    )
)
def test_parameters_round_trip_any_json(values: dict) -> None:
    case = Case(parameters=values)
    assert thaw_json(case.parameters) == json.loads(json.dumps(values))
    assert json_round_trip(case).equals(case)


finite = st.floats(-500, 500, allow_nan=False)
landmark_st = st.builds(
    lambda code, pos, status, conf, desc: Landmark(code, pos, status, conf, desc),
    st.sampled_from(["n", "g", "pg", "zy_l", "zy_r", "prn"]),
    st.tuples(finite, finite, finite),
    st.sampled_from(["placed", "suggested", "absent", "missing"]),
    st.floats(0, 1),
    st.text(max_size=6),
)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(landmark_st, max_size=6, unique_by=lambda lm: lm.code),
    st.sampled_from(["skin", "skull"]),
)
def test_landmark_sets_round_trip(landmarks: list, surface: str) -> None:
    lmset = LandmarkSet(surface, tuple(landmarks))
    state = json.loads(json.dumps(landmark_set_to_state(lmset), allow_nan=False))
    assert landmark_set_from_state(state).equals(lmset)


def test_frozen_json_rejects_non_json() -> None:
    with pytest.raises(TypeError, match="set"):
        freeze_json({"a": {1, 2}}, "parameters")
    assert freeze_json(np.int64(3)) == 3
    assert type(freeze_json(np.float32(0.5))) is float


def test_module_docstring_fixes_units_and_frames() -> None:
    doc = case_module.__doc__ or ""
    for phrase in (
        "Notes",
        "millimetres",
        "radians",
        "degrees",
        "input frame",
        "Frankfort",
        "input_to_head",
    ):
        assert phrase in doc
