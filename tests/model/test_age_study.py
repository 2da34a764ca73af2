"""The case part ``age_study``: validation, state round trip, case files with and without it."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import pytest

from workbench.core.errors import InputError
from workbench.io.case_file import load_case, save_case
from workbench.io.migrations import migrate
from workbench.model.age_study import AgeStudy, AgeStudyError
from workbench.model.case import Case

STUDY = AgeStudy(
    source="reference:female",
    sex="female",
    from_age=30,
    target_ages=(12, 5.5, 40),
    norms="facial_norms",
    ethnicity="European",
    arc_increase=0.05,
)


def test_values_are_normalised_and_kept_in_order() -> None:
    assert STUDY.from_age == 30.0 and isinstance(STUDY.from_age, float)
    assert STUDY.target_ages == (12.0, 5.5, 40.0)  # the first is the slider's
    assert AgeStudy(target_ages=7).target_ages == (7.0,)
    assert AgeStudy(ethnicity=" Asian ").ethnicity == "Asian"
    assert STUDY.replaced(sex="male") != STUDY
    assert STUDY.replaced(sex="male").changed_fields(STUDY) == ("sex",)
    assert len(STUDY.changed_fields(None)) == 7


def test_state_round_trip_is_plain_json() -> None:
    state = STUDY.to_state()
    assert json.loads(json.dumps(state)) == state
    assert state["target_ages"] == [12.0, 5.5, 40.0]
    assert AgeStudy.from_state(state) == STUDY
    case = Case(age_study=STUDY)
    again = Case.from_state(case.to_state())
    assert again.age_study == STUDY and again.equals(case)
    assert Case().age_study is None
    assert Case.from_state(Case().to_state()).age_study is None


@pytest.mark.parametrize(
    ("fields", "where", "problem"),
    [
        ({"source": "fit"}, "age study source", "unknown head 'fit'"),
        ({"sex": "unknown"}, "age study sex", "not one of female, male"),
        ({"from_age": -1}, "age now", "-1 is not an age in years in 0-100"),
        ({"from_age": float("nan")}, "age now", "not an age"),
        ({"from_age": True}, "age now", "not an age"),
        ({"target_ages": (5, 120)}, "target age", "120 is not an age in years in 0-100"),
        ({"target_ages": ()}, "target age", "at least one target age"),
        ({"target_ages": (5, 5.0)}, "target age", "5 y given twice"),
        ({"target_ages": "5"}, "target age", "not an age"),
        ({"arc_increase": 0.2}, "arc increase", "0.2 is not a fraction in 0-0.1"),
        ({"norms": " "}, "norms", "non-empty text"),
        ({"ethnicity": ""}, "norms population", "non-empty text"),
    ],
)
def test_bad_values_are_refused_with_a_clear_message(fields, where, problem) -> None:
    with pytest.raises(AgeStudyError) as info:
        AgeStudy(**fields)
    error = info.value
    assert isinstance(error, InputError) and isinstance(error, ValueError)
    assert error.source == where
    assert problem in str(error)


def test_from_state_refuses_unknown_and_missing_fields() -> None:
    with pytest.raises(AgeStudyError, match="unknown fields colour"):
        AgeStudy.from_state({**STUDY.to_state(), "colour": "red"})
    state = STUDY.to_state()
    del state["norms"]
    with pytest.raises(AgeStudyError, match="missing fields norms"):
        AgeStudy.from_state(state)
    with pytest.raises(TypeError, match="expected AgeStudy"):
        Case(age_study=STUDY.to_state())


def test_saved_and_reloaded_case_keeps_the_study(tmp_path: Path) -> None:
    case = Case(age_study=STUDY)
    path = save_case(case, tmp_path / "aged.fcase")
    with zipfile.ZipFile(path) as archive:
        doc = json.loads(archive.read("case.json"))
    assert doc["format_version"] == 3
    assert doc["age_study"] == STUDY.to_state()
    loaded = load_case(path).case
    assert loaded.age_study == STUDY and loaded.equals(case)
    empty = load_case(save_case(Case(), tmp_path / "none.fcase")).case
    assert empty.age_study is None


def _as_format_2(path: Path, out: Path) -> Path:
    """``path`` rewritten as the previous software wrote it (format 2, no age_study)."""
    with zipfile.ZipFile(path) as source:
        members = {n: source.read(n) for n in source.namelist()}
    doc = json.loads(members.pop("case.json"))
    assert doc.pop("age_study") is None
    doc.update({"@schema": "case-schema-v2", "format_version": 2})
    with zipfile.ZipFile(out, "w") as archive:
        archive.writestr("case.json", json.dumps(doc))
        for name, data in members.items():
            archive.writestr(name, data)
    return out


def test_a_format_2_file_without_the_part_loads_with_no_study(tmp_path: Path) -> None:
    case = Case()
    old = _as_format_2(save_case(case, tmp_path / "new.fcase"), tmp_path / "old.fcase")
    with zipfile.ZipFile(old) as archive:
        doc = json.loads(archive.read("case.json"))
    assert "age_study" not in doc
    upgraded, applied = migrate(doc)
    assert applied == [2] and upgraded["age_study"] is None
    loaded = load_case(old)
    assert loaded.case.age_study is None
    assert loaded.case.meta.case_id == case.meta.case_id and not loaded.tampered
    # a format-2 document that already names the part is not a format-2 document
    with pytest.raises(ValueError, match="cannot upgrade format_version 2"):
        migrate({**doc, "age_study": STUDY.to_state()})


def test_a_bad_study_in_a_file_is_refused_naming_the_part(tmp_path: Path) -> None:
    from workbench.io.case_file import CaseFileError

    path = save_case(Case(age_study=STUDY), tmp_path / "aged.fcase")
    with zipfile.ZipFile(path) as source:
        members = {n: source.read(n) for n in source.namelist()}
    doc = json.loads(members.pop("case.json"))
    doc["age_study"]["arc_increase"] = 0.5
    bad = tmp_path / "bad.fcase"
    with zipfile.ZipFile(bad, "w") as archive:
        archive.writestr("case.json", json.dumps(doc))
        for name, data in members.items():
            archive.writestr(name, data)
    with pytest.raises(CaseFileError, match="age_study"):
        load_case(bad, allow_tampered=True)
