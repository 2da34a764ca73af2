"""Typed reconstruction settings: dowels, orientation, guides (values, state, validation)."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from workbench.core.errors import InputError
from workbench.model.reconstruction_setup import (
    FACTOR_RANGE,
    MAX_DEPTH_MM,
    REGIONS,
    TISSUE_MODELS,
    DowelSettings,
    GuideList,
    Orientation,
    SetupError,
    build_text,
    parse_build,
)


def json_again(state: object) -> object:
    return json.loads(json.dumps(state, allow_nan=False))


# ---------------------------------------------------------------- dowels
def test_dowel_defaults() -> None:
    d = DowelSettings()
    assert (d.table, d.sex, d.build, d.tissue_model) == ("ttable_2023", "male", "normal", "table")
    assert dict(d.overrides) == {} and d.excluded == () and dict(d.region_factors) == {}
    assert d.to_state() == {
        "table": "ttable_2023",
        "sex": "male",
        "build": "normal",
        "overrides": {},
        "excluded": [],
        "tissue_model": "table",
        "region_factors": {},
        "jaw": "occlusion",
    }


def test_the_jaw_position_is_checked_and_older_cases_without_it_close_the_jaw() -> None:
    assert DowelSettings(jaw="as-scanned").to_state()["jaw"] == "as-scanned"
    with pytest.raises(SetupError, match="jaw"):
        DowelSettings(jaw="open")
    state = DowelSettings().to_state()
    del state["jaw"]  # a case saved before the setting existed
    assert DowelSettings.from_state(state).jaw == "occlusion"


def test_dowels_normalise_and_compare_by_value() -> None:
    a = DowelSettings(
        table=" ttable_2023 ",
        build="1.5",
        overrides={"n": 7, "g": 6.5},
        excluded=["zy_r", "zy_l", "zy_r"],
        region_factors={"nose": 1.2},
    )
    b = DowelSettings(
        build=1.5,
        overrides={"g": 6.5, "n": 7.0},
        excluded=("zy_l", "zy_r"),
        region_factors={"nose": 1.2},
    )
    assert a == b and hash(a) == hash(b)
    assert a.table == "ttable_2023" and a.build == 1.5 and a.build_text == "1.5"
    assert list(a.overrides) == ["g", "n"] and a.excluded == ("zy_l", "zy_r")
    assert a != DowelSettings(build=1.5)
    with pytest.raises(TypeError):
        a.overrides["g"] = 1.0  # type: ignore[index]


@settings(max_examples=60, deadline=None)
@given(
    table=st.sampled_from(["ttable_2023", "rhine_1983_sw_native_american", "/x/my table.csv"]),
    sex=st.sampled_from(["female", "male"]),
    build=st.one_of(
        st.sampled_from(["slender", "normal", "obese"]), st.floats(-4, 4, allow_nan=False)
    ),
    overrides=st.dictionaries(
        st.sampled_from(["g", "n", "pg", "i:vault_1"]),
        st.floats(0.1, MAX_DEPTH_MM, allow_nan=False),
        max_size=3,
    ),
    excluded=st.lists(st.sampled_from(["g", "ecm2s_l", "zy_r"]), max_size=3),
    model=st.sampled_from(TISSUE_MODELS),
    factors=st.dictionaries(st.sampled_from(REGIONS), st.floats(*FACTOR_RANGE), max_size=3),
)
def test_dowels_round_trip_through_json(
    table, sex, build, overrides, excluded, model, factors
) -> None:
    d = DowelSettings(table, sex, build, overrides, excluded, model, factors)
    again = DowelSettings.from_state(json_again(d.to_state()))
    assert again == d and again.to_state() == d.to_state()


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"table": ""}, "depth table"),
        ({"sex": "unknown"}, "sex"),
        ({"sex": None}, "sex"),
        ({"build": "slim"}, "unknown build"),
        ({"build": True}, "unknown build"),
        ({"build": math.inf}, "finite"),
        ({"overrides": {"g": 0.0}}, "depth override g"),
        ({"overrides": {"g": -1.0}}, "depth override g"),
        ({"overrides": {"g": math.nan}}, "depth override g"),
        ({"overrides": {"g": 250.0}}, "depth override g"),
        ({"overrides": {"g": "six"}}, "depth override g"),
        ({"overrides": {"": 5.0}}, "landmark code"),
        ({"overrides": [("g", 5.0)]}, "mapping"),
        ({"excluded": "g"}, "list of codes"),
        ({"excluded": ["g", 3]}, "landmark code"),
        ({"tissue_model": "rubber"}, "tissue model"),
        ({"region_factors": {"ears": 1.0}}, "unknown region"),
        ({"region_factors": {"nose": 5.0}}, "outside 0.3-3"),
        ({"region_factors": {"nose": math.nan}}, "outside"),
    ],
)
def test_invalid_dowel_settings_are_refused(fields: dict, message: str) -> None:
    with pytest.raises(SetupError, match=message) as info:
        DowelSettings(**fields)
    assert isinstance(info.value, InputError) and isinstance(info.value, ValueError)


def test_dowel_state_with_unknown_fields_is_refused() -> None:
    with pytest.raises(SetupError, match="unknown fields colour"):
        DowelSettings.from_state({**DowelSettings().to_state(), "colour": "red"})


def test_override_and_exclusion_helpers() -> None:
    d = DowelSettings().with_override("g", 6.5).with_exclusion("n", True)
    assert dict(d.overrides) == {"g": 6.5} and d.excluded == ("n",)
    assert d.with_override("g", None) == DowelSettings(excluded=("n",))
    assert d.with_exclusion("n", False).excluded == ()
    assert d.with_exclusion("zz", False) == d
    with pytest.raises(SetupError):
        d.with_override("g", -3.0)


def test_build_parsing() -> None:
    assert parse_build("Normal") == "normal"
    assert parse_build("-1 SD") == -1.0 and parse_build(2) == 2.0
    assert build_text(-1.0) == "-1" and build_text(1.5) == "1.5" and build_text("obese") == "obese"


def test_region_constants_match_the_tissue_model() -> None:
    from workbench.services.tissue import tissue_model

    assert REGIONS == tissue_model.REGIONS
    assert FACTOR_RANGE == tissue_model.FACTOR_RANGE
    assert TISSUE_MODELS == tissue_model.MODELS


# ---------------------------------------------------------------- orientation
def test_orientation_stores_unit_vectors_and_round_trips() -> None:
    o = Orientation((0, -2, 0), (0.0, 0.0, -0.5))
    assert o.anterior == (0.0, -1.0, 0.0) and o.superior == (0.0, 0.0, -1.0) and o.left is None
    assert o.hint == ((0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
    assert Orientation.from_state(json_again(o.to_state())) == o
    m = Orientation.from_hint([(0, -1, 0), (0, 0, -1), (3, 0, 0)])
    assert m.left == (1.0, 0.0, 0.0) and len(m.hint) == 3
    assert Orientation.from_state(json_again(m.to_state())) == m != o
    assert hash(m) == hash(Orientation.from_state(m.to_state()))


@settings(max_examples=80, deadline=None)
@given(
    st.tuples(*[st.floats(-10, 10, allow_nan=False)] * 3),
    st.tuples(*[st.floats(-10, 10, allow_nan=False)] * 3),
)
def test_orientation_state_is_a_fixed_point(a: tuple, s: tuple) -> None:
    try:
        o = Orientation(a, s)
    except SetupError:
        return
    again = Orientation.from_state(json_again(o.to_state()))
    assert again == o and again.to_state() == o.to_state()
    assert math.isclose(sum(x * x for x in o.anterior), 1.0, rel_tol=1e-12)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (((0, 0, 0), (0, 1, 0)), "zero length"),
        (((0, 0, 1), (0, 0, -3)), "parallel"),
        (((0, 0, 1), (0, 1)), "3 finite numbers"),
        (((0, 0, math.nan), (0, 1, 0)), "3 finite numbers"),
        (((0, 0, 1), (0, 1, 0), (1, 0, "x")), "3 finite numbers"),
    ],
)
def test_invalid_orientations_are_refused(args: tuple, message: str) -> None:
    with pytest.raises(SetupError, match=message):
        Orientation(*args)
    with pytest.raises(SetupError, match="anterior, superior"):
        Orientation.from_hint([(0, 0, 1)])


# ---------------------------------------------------------------- guides
GUIDE = {
    "id": "nose_tip",
    "label": "Nose tip",
    "kind": "point",
    "view": "lateral",
    "value": [-20.0, 95.0],
    "affects": ["prn"],
    "rule_id": "r",
    "citation": "c",
    "source": "user",
    "enabled": True,
    "derivation": "",
}


def test_guide_list_is_frozen_json_and_round_trips() -> None:
    g = GuideList([GUIDE, {**GUIDE, "id": "lip_parting", "kind": "hline", "value": [-70.0]}])
    assert len(g) == 2 and g.ids == ("nose_tip", "lip_parting")
    assert g.to_state()[0] == GUIDE
    assert GuideList.from_state(json_again(g.to_state())) == g
    assert hash(g) == hash(GuideList.from_state(g.to_state()))
    with pytest.raises(TypeError):
        g.guides[0]["value"] = [1.0]  # type: ignore[index]
    assert GuideList() == GuideList.from_state([]) and len(GuideList()) == 0


def test_guide_list_matches_the_services_json() -> None:
    from workbench.services.guides.classic import guides_from_json, guides_to_json

    guides = guides_from_json([GUIDE])
    stored = GuideList(tuple(guides_to_json(guides)))
    assert guides_from_json(stored.to_state()) == guides


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"guides": []}, "list of guides"),
        ("nose", "list of guides"),
        ([GUIDE, GUIDE], "duplicate guide ids: nose_tip"),
        ([{**GUIDE, "id": ""}], "non-empty text id"),
        ([{**GUIDE, "value": []}], "1 or 2 numbers"),
        ([{**GUIDE, "value": [1.0, "x"]}], "1 or 2 numbers"),
        ([["nose_tip", 1.0]], "expected an object"),
    ],
)
def test_invalid_guide_lists_are_refused(value: object, message: str) -> None:
    with pytest.raises(SetupError, match=message):
        GuideList(value)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="non-finite"):
        GuideList([{**GUIDE, "value": [math.inf]}])
