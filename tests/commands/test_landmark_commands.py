"""Landmark commands: what each does, what it refuses, and its labels."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.commands.landmarks import (
    DeleteLandmark,
    MoveLandmark,
    PlaceLandmark,
    ReplaceLandmarkSet,
    SetLandmarkStatus,
)
from workbench.commands.stack import CommandStack
from workbench.core.errors import LandmarkError
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.model.case import Case


@pytest.fixture
def case() -> Case:
    skull = LandmarkSet(
        "skull",
        (
            Landmark("n", [0.0, 50.0, 80.0], description="nasion, checked twice"),
            Landmark("zy_l", [60.0, 20.0, 40.0], "suggested", 0.25),
            Landmark("pg", [np.nan] * 3, "absent"),
        ),
    )
    return Case(landmarks={"skull": skull})


def test_place_adds_and_keeps_description(case: Case, stack: CommandStack) -> None:
    stack.push(PlaceLandmark("skull", "g", [1, 2, 3]))
    stack.push(PlaceLandmark("skull", "n", [0, 49, 81]))
    skull = case.landmarks["skull"]
    assert skull.codes == ("n", "zy_l", "pg", "g")
    assert skull["n"].position.tolist() == [0, 49, 81]
    assert skull["n"].description == "nasion, checked twice"
    assert skull["g"].status == "placed"
    assert skull["g"].confidence == 1.0


def test_place_over_absent_defines_it(case: Case, stack: CommandStack) -> None:
    stack.push(PlaceLandmark("skull", "pg", [0, -60, 70]))
    assert case.landmarks["skull"]["pg"].status == "placed"


def test_move_confirms_a_suggestion(case: Case, stack: CommandStack) -> None:
    stack.push(MoveLandmark("skull", "zy_l", [61, 20, 40]))
    lm = case.landmarks["skull"]["zy_l"]
    assert lm.status == "placed"
    assert lm.confidence == 1.0
    stack.undo()
    assert case.landmarks["skull"]["zy_l"].status == "suggested"


def test_move_refuses_missing_or_undefined(stack: CommandStack) -> None:
    with pytest.raises(LandmarkError, match="no skull landmark 'g'"):
        stack.push(MoveLandmark("skull", "g", [0, 0, 0]))
    with pytest.raises(LandmarkError, match="absent"):
        stack.push(MoveLandmark("skull", "pg", [0, 0, 0]))
    assert len(stack) == 0


def test_mark_absent_clears_position(case: Case, stack: CommandStack) -> None:
    stack.push(SetLandmarkStatus("skull", "n", "absent"))
    lm = case.landmarks["skull"]["n"]
    assert lm.status == "absent"
    assert np.isnan(lm.position).all()
    assert lm.description == "nasion, checked twice"
    assert stack.undo_text == "Mark skull landmark n absent"
    stack.undo()
    assert case.landmarks["skull"]["n"].position.tolist() == [0, 50, 80]


def test_mark_absent_creates_a_new_entry(case: Case, stack: CommandStack) -> None:
    stack.push(SetLandmarkStatus("skin", "prn", "absent"))
    assert case.landmarks["skin"]["prn"].status == "absent"


def test_confirm_and_unconfirm(case: Case, stack: CommandStack) -> None:
    stack.push(SetLandmarkStatus("skull", "zy_l", "placed"))
    assert case.landmarks["skull"]["zy_l"].confidence == 1.0
    stack.push(SetLandmarkStatus("skull", "n", "suggested"))
    assert case.landmarks["skull"]["n"].status == "suggested"
    with pytest.raises(LandmarkError, match="no position"):
        stack.push(SetLandmarkStatus("skull", "pg", "placed"))
    with pytest.raises(LandmarkError, match="no position"):
        stack.push(SetLandmarkStatus("skull", "g", "suggested"))


def test_delete(case: Case, stack: CommandStack) -> None:
    stack.push(DeleteLandmark("skull", "zy_l"))
    assert case.landmarks["skull"].codes == ("n", "pg")
    stack.undo()
    assert case.landmarks["skull"].codes == ("n", "zy_l", "pg")  # order restored
    with pytest.raises(LandmarkError, match="no skin landmark"):
        stack.push(DeleteLandmark("skin", "n"))


def test_replace_set_for_suggestions(case: Case, stack: CommandStack) -> None:
    suggested = LandmarkSet.from_points(
        "skin", {"prn": (0, 10, 100), "sn": (0, 0, 90)}, "suggested"
    )
    stack.push(ReplaceLandmarkSet("skin", suggested, "Suggest skin landmarks"))
    assert case.landmarks["skin"] is suggested
    assert stack.undo_text == "Suggest skin landmarks"
    assert ReplaceLandmarkSet("skin", suggested).label == "Replace skin landmarks"
    with pytest.raises(LandmarkError, match="skin landmark set on the skull"):
        ReplaceLandmarkSet("skull", suggested)
    params = stack._undo[-1].parameters()
    assert params["surface"] == "skin"
    assert len(params["new_set"]["landmarks"]) == 2


@pytest.mark.parametrize(
    "build",
    [
        lambda: PlaceLandmark("bone", "n", [0, 0, 0]),
        lambda: PlaceLandmark("skull", "", [0, 0, 0]),
        lambda: PlaceLandmark("skull", "n", [0, 0]),
        lambda: PlaceLandmark("skull", "n", [0, np.nan, 0]),
        lambda: MoveLandmark("skull", "n", [np.inf, 0, 0]),
        lambda: SetLandmarkStatus("skull", "n", "lost"),
    ],
)
def test_bad_arguments_fail_at_construction(build) -> None:
    with pytest.raises(LandmarkError):
        build()


def test_positions_are_copied_and_read_only(case: Case, stack: CommandStack) -> None:
    where = np.array([1.0, 2.0, 3.0])
    command = PlaceLandmark("skull", "g", where)
    where[0] = 99.0
    stack.push(command)
    assert case.landmarks["skull"]["g"].position.tolist() == [1, 2, 3]
    with pytest.raises(ValueError, match="read-only"):
        command.position[0] = 5.0


def test_labels_and_audit_parameters(case: Case, stack: CommandStack) -> None:
    stack.push(PlaceLandmark("skin", "prn", [0, 1.5, 2]))
    stack.push(MoveLandmark("skin", "prn", [0, 1.5, 3]))
    stack.push(DeleteLandmark("skin", "prn"))
    labels = [r["operation"] for r in case.audit.records]
    assert labels == [
        "Place skin landmark prn",
        "Move skin landmark prn",
        "Delete skin landmark prn",
    ]
    assert case.audit.records[1]["parameters"] == {
        "surface": "skin",
        "code": "prn",
        "position": [0.0, 1.5, 3.0],
    }


def test_events_fire_once_per_change(case: Case, stack: CommandStack) -> None:
    seen: list[str] = []
    case.events.changed.connect(seen.append)
    stack.push(PlaceLandmark("skull", "g", [1, 2, 3]))
    stack.undo()
    assert seen == ["landmarks", "landmarks"]
