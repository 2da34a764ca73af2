"""The case part ``appearance`` (issue 34, colouring): validation, state, case files with and
without it (an optional part: older files, which lack it, open with no colours)."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import pytest

from workbench.io.case_file import CaseFileError, load_case, save_case
from workbench.io.migrations import migrate
from workbench.model.appearance import ARTISTIC_NOTE, REGIONS, Appearance, AppearanceError, Hsv
from workbench.model.case import PARTS, Case

LOOK = Appearance(
    tone="mst4",
    regions={"lips": (0.02, 0.55, 0.6), "brows": Hsv(0.08, 0.4, 0.25)},
    iris="hazel",
)


def test_defaults_state_and_equality() -> None:
    a = Appearance()
    assert (a.tone, a.regions, a.iris) == ("medium", (), "brown")
    assert LOOK.colour("lips") == Hsv(0.02, 0.55, 0.6)
    assert LOOK.colour("cheeks") is None and not LOOK.custom_base
    # regions are kept in REGIONS order whatever order they came in
    assert [r for r, _ in LOOK.regions] == [r for r in REGIONS if r in ("lips", "brows")]
    state = LOOK.to_state()
    assert state == {
        "tone": "mst4",
        "regions": {"brows": [0.08, 0.4, 0.25], "lips": [0.02, 0.55, 0.6]},
        "iris": "hazel",
    }
    again = Appearance.from_state(json.loads(json.dumps(state)))
    assert again == LOOK and hash(again) == hash(LOOK)
    assert Hsv(1.0, 0.5, 0.5).h == 0.0  # a full turn is red again
    assert "not evidence" in ARTISTIC_NOTE


def test_copies() -> None:
    custom = LOOK.with_colour("skin", Hsv(0.07, 0.3, 0.8))
    assert custom.custom_base and custom.tone == "mst4"
    back = custom.with_tone("dark")
    assert not back.custom_base and back.tone == "dark" and back.colour("lips") is not None
    assert LOOK.with_colour("lips", None).colour("lips") is None
    assert set(custom.changed_fields(LOOK)) == {"skin"}
    assert set(back.changed_fields(LOOK)) == {"tone"}
    assert set(LOOK.changed_fields(None)) == {"tone", "iris", "lips", "brows"}


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tone": "beige"}, "unknown preset 'beige'"),
        ({"iris": "violet"}, "unknown 'violet'"),
        ({"regions": {"nose": (0, 0, 0)}}, "unknown region 'nose'"),
        ({"regions": {"lips": (0.1, 1.5, 0.2)}}, "lips colour: 1.5 is not a fraction"),
        ({"regions": {"lips": (0.1, 0.5)}}, "expected \\[hue, saturation, value\\]"),
        ({"regions": {"lips": ("0.1", 0.5, 0.5)}}, "'0.1' is not a fraction"),
        ({"regions": (("lips", (0, 0, 0)), ("lips", (0, 0, 0)))}, "'lips' given twice"),
    ],
)
def test_bad_values_are_refused_with_clear_messages(kwargs: dict, message: str) -> None:
    with pytest.raises(AppearanceError, match=message):
        Appearance(**kwargs)


def test_bad_states_are_refused() -> None:
    with pytest.raises(AppearanceError, match="missing fields iris"):
        Appearance.from_state({"tone": "mst1", "regions": {}})
    with pytest.raises(AppearanceError, match="unknown fields hair"):
        Appearance.from_state({**LOOK.to_state(), "hair": "red"})
    with pytest.raises(AppearanceError, match="expected an object"):
        Appearance.from_state([1, 2])
    with pytest.raises(TypeError, match="expected Appearance"):
        Case(appearance=LOOK.to_state())


def test_the_part_is_registered_optional_and_none_by_default() -> None:
    assert PARTS["appearance"].optional
    assert Case().appearance is None
    case = Case(appearance=LOOK)
    assert Case.from_state(case.to_state()).appearance == LOOK
    assert Case.from_state(Case().to_state()).appearance is None


def _doc(path: Path) -> dict:
    with zipfile.ZipFile(path) as archive:
        return json.loads(archive.read("case.json"))


def test_saved_and_reloaded_case_keeps_its_colours(tmp_path: Path) -> None:
    case = Case(appearance=LOOK)
    path = save_case(case, tmp_path / "coloured.fcase")
    assert _doc(path)["appearance"] == LOOK.to_state()
    loaded = load_case(path)
    assert loaded.case.appearance == LOOK and loaded.case.equals(case)
    assert not loaded.tampered


def test_a_file_without_the_part_opens_with_no_colours(tmp_path: Path) -> None:
    """A case with no colours is written without the key, as every file before the part
    was; it opens (sealed, not tampered) with ``appearance is None``."""
    case = Case()
    path = save_case(case, tmp_path / "plain.fcase")
    doc = _doc(path)
    assert "appearance" not in doc and doc["format_version"] == 3
    assert migrate(doc) == (doc, [])
    loaded = load_case(path)
    assert loaded.case.appearance is None and not loaded.tampered
    assert loaded.case.equals(case)


def test_a_format_2_file_opens_with_no_colours(tmp_path: Path) -> None:
    """An older format (no age_study, no appearance) migrates and opens without colours."""
    case = Case()
    path = save_case(case, tmp_path / "new.fcase")
    with zipfile.ZipFile(path) as source:
        members = {n: source.read(n) for n in source.namelist()}
    doc = json.loads(members.pop("case.json"))
    assert doc.pop("age_study") is None and "appearance" not in doc
    doc.update({"@schema": "case-schema-v2", "format_version": 2})
    old = tmp_path / "old.fcase"
    with zipfile.ZipFile(old, "w") as archive:
        archive.writestr("case.json", json.dumps(doc))
        for name, data in members.items():
            archive.writestr(name, data)
    loaded = load_case(old)
    assert loaded.case.appearance is None and not loaded.tampered


def _rewrite(path: Path, out: Path, edit) -> Path:
    with zipfile.ZipFile(path) as source:
        members = {n: source.read(n) for n in source.namelist()}
    doc = json.loads(members.pop("case.json"))
    edit(doc)
    with zipfile.ZipFile(out, "w") as archive:
        archive.writestr("case.json", json.dumps(doc))
        for name, data in members.items():
            archive.writestr(name, data)
    return out


def test_colours_removed_from_a_sealed_file_are_a_tamper(tmp_path: Path) -> None:
    """The key dropped from a file that had it: the seal no longer matches (refused), and
    with ``allow_tampered`` the case opens without colours and says it was changed."""
    path = save_case(Case(appearance=LOOK), tmp_path / "coloured.fcase")
    cut = _rewrite(path, tmp_path / "cut.fcase", lambda d: d.pop("appearance"))
    with pytest.raises(CaseFileError, match="case.json"):
        load_case(cut)
    loaded = load_case(cut, allow_tampered=True)
    assert loaded.case.appearance is None and loaded.tampered


def test_bad_colours_in_a_file_are_refused(tmp_path: Path) -> None:
    path = save_case(Case(appearance=LOOK), tmp_path / "coloured.fcase")
    bad = _rewrite(
        path, tmp_path / "bad.fcase", lambda d: d["appearance"]["regions"].update(nose=[0, 0, 0])
    )
    with pytest.raises(CaseFileError, match="appearance"):
        load_case(bad, allow_tampered=True)
    unknown = _rewrite(
        path, tmp_path / "tone.fcase", lambda d: d["appearance"].update(tone="beige")
    )
    with pytest.raises(CaseFileError, match="beige"):
        load_case(unknown, allow_tampered=True)


def test_hair_and_brow_styles_are_part_of_the_colours(tmp_path: Path) -> None:
    """The styles of the hair library (issue 34): validated, kept in the case file, absent
    from the state when none is chosen (older files read as before)."""
    groomed = LOOK.with_style("hair", "medium").with_style("brows", "thin")
    assert groomed.style("hair") == "medium" and groomed.style("beard") == "none"
    assert groomed.grooming == (("hair", "medium"), ("brows", "thin"))
    assert groomed.with_style("hair", "none").grooming == (("brows", "thin"),)
    assert set(groomed.changed_fields(LOOK)) == {"hair style", "brows style"}
    assert "grooming" not in LOOK.to_state()
    assert groomed.to_state()["grooming"] == {"hair": "medium", "brows": "thin"}
    assert Appearance.from_state(groomed.to_state()) == groomed
    case = Case(appearance=groomed)
    path = save_case(case, tmp_path / "groomed.fcase")
    assert _doc(path)["appearance"]["grooming"] == {"hair": "medium", "brows": "thin"}
    assert load_case(path).case.appearance == groomed
    with pytest.raises(AppearanceError, match="unknown 'mohawk'"):
        Appearance(grooming={"hair": "mohawk"})
    with pytest.raises(AppearanceError, match="unknown kind 'wig'"):
        Appearance(grooming={"wig": "long"})
    with pytest.raises(AppearanceError, match="expected an object"):
        Appearance.from_state({**LOOK.to_state(), "grooming": ["hair", "long"]})
    assert Appearance(regions={"hair": (0.1, 0.3, 0.2)}).colour("hair") == Hsv(0.1, 0.3, 0.2)
