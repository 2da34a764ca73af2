"""Commands on the typed reconstruction settings: labels, merging, audit, refusals."""

from __future__ import annotations

import json

import pytest

from workbench.commands.reconstruction_setup import (
    SetDepthOverride,
    SetDowelExclusion,
    SetDowelSettings,
    SetGuides,
    SetOrientation,
)
from workbench.commands.stack import CommandError, CommandStack
from workbench.core.errors import WorkbenchError
from workbench.model.case import Case
from workbench.model.reconstruction_setup import DowelSettings, GuideList, Orientation


def test_dowel_settings_change_only_the_fields_given(case: Case, stack: CommandStack) -> None:
    stack.push(SetDowelSettings(sex="female", excluded=["ecm2s_l"]))
    stack.push(SetDowelSettings(build="-1"))
    assert case.dowels == DowelSettings(sex="female", build=-1.0, excluded=("ecm2s_l",))
    assert stack.undo_text == "Set build -1"
    stack.undo()
    assert case.dowels == DowelSettings(sex="female", excluded=("ecm2s_l",))
    stack.undo()
    assert case.dowels == DowelSettings()


def test_consecutive_edits_of_one_field_merge(case: Case, stack: CommandStack) -> None:
    for k in ("1", "1.5", "2"):  # a combo box run through: one step
        stack.push(SetDowelSettings(build=k))
    stack.push(SetDowelSettings(table="rhine_1983_sw_native_american"))
    assert len(stack) == 2 and stack.undo_text == "Choose depth table"
    stack.undo()
    assert case.dowels.build == 2.0 and stack.undo_text == "Set build 2"
    stack.undo()
    assert case.dowels == DowelSettings()
    stack.redo()
    assert case.dowels.build == 2.0


def test_depth_overrides_merge_per_code_and_clear(case: Case, stack: CommandStack) -> None:
    stack.push(SetDepthOverride("g", 6.0))
    stack.push(SetDepthOverride("g", 6.5))
    stack.push(SetDepthOverride("n", 9.0))
    assert len(stack) == 2 and dict(case.dowels.overrides) == {"g": 6.5, "n": 9.0}
    stack.push(SetDepthOverride("g", None))
    assert dict(case.dowels.overrides) == {"n": 9.0}
    assert stack.undo_text == "Use the table depth for g"
    with pytest.raises(CommandError, match="not overridden"):
        stack.push(SetDepthOverride("g", None))
    assert len(stack) == 3
    stack.undo()
    assert case.dowels.overrides["g"] == 6.5


def test_exclusions(case: Case, stack: CommandStack) -> None:
    stack.push(SetDowelExclusion("ecm2s_l", True))
    stack.push(SetDowelExclusion("n", True))
    assert case.dowels.excluded == ("ecm2s_l", "n") and stack.undo_text == "Exclude dowel n"
    stack.push(SetDowelExclusion("n", False))
    assert case.dowels.excluded == ("ecm2s_l",) and stack.undo_text == "Use dowel n"


def test_orientation_and_guides(case: Case, stack: CommandStack) -> None:
    seen: list[str] = []
    case.events.changed.connect(seen.append)
    stack.push(SetOrientation(((0, -1, 0), (0, 0, -1))))
    assert case.orientation == Orientation((0, -1, 0), (0, 0, -1))
    assert stack.undo_text == "Set skull orientation"
    stack.push(SetOrientation(None))
    assert case.orientation is None and stack.undo_text == "Automatic orientation"
    guides = [{"id": "nose_tip", "value": [-20.0, 95.0], "source": "user"}]
    stack.push(SetGuides(guides, label="Move guide nose_tip"))
    assert case.guides == GuideList(tuple(guides))
    stack.push(SetGuides(None))
    assert case.guides is None and stack.undo_text == "Recompute guides"
    stack.undo()
    assert case.guides.ids == ("nose_tip",)  # type: ignore[union-attr]
    assert seen == ["orientation", "orientation", "guides", "guides", "guides"]


def test_audit_records_name_the_settings_and_tables(case: Case, stack: CommandStack) -> None:
    stack.push(SetDowelSettings(table="ttable_2023", overrides={"g": 6.5}))
    stack.push(SetOrientation(((0, 0, 1), (0, 1, 0), (1, 0, 0))))
    stack.push(SetGuides([{"id": "nose_tip", "value": [-20.0, 95.0]}]))
    stack.push(SetDepthOverride("n", 7.0))
    records = case.audit.records
    json.dumps(records, allow_nan=False)
    assert records[0]["parameters"] == {"table": "ttable_2023", "overrides": {"g": 6.5}}
    assert records[0]["table_ids"] == ["ttable_2023"]
    assert records[1]["parameters"]["orientation"]["left"] == [1.0, 0.0, 0.0]
    assert records[2]["parameters"]["guides"][0]["id"] == "nose_tip"
    assert records[3]["parameters"] == {"code": "n", "depth_mm": 7.0}
    assert [r["command"] for r in records] == [
        "SetDowelSettings",
        "SetOrientation",
        "SetGuides",
        "SetDepthOverride",
    ]


@pytest.mark.parametrize(
    "make",
    [
        lambda: SetDowelSettings(),
        lambda: SetDowelSettings(sex="unknown"),
        lambda: SetDowelSettings(build="slim"),
        lambda: SetDepthOverride("g", -1.0),
        lambda: SetDepthOverride("", 5.0),
        lambda: SetDowelExclusion("", True),
        lambda: SetOrientation(((0, 0, 1), (0, 0, 2))),
        lambda: SetGuides([{"id": "a", "value": [1.0]}, {"id": "a", "value": [2.0]}]),
    ],
)
def test_bad_values_fail_when_the_command_is_built(make) -> None:
    with pytest.raises(WorkbenchError):
        make()
