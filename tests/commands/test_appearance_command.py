"""SetAppearance: one undo step, audited, merging moves of one region (issue 34, colouring)."""

from __future__ import annotations

import pytest

from workbench.commands.appearance import SetAppearance
from workbench.commands.case_edits import SetParameter
from workbench.commands.stack import CommandError, CommandStack
from workbench.model.appearance import ARTISTIC_NOTE, Appearance, AppearanceError, Hsv
from workbench.model.case import Case


def test_set_undo_redo_and_audit() -> None:
    case = Case()
    stack = CommandStack(case)
    look = Appearance(tone="mst2", regions={"lips": (0.0, 0.5, 0.5)}, iris="blue")
    stack.push(SetAppearance(look))
    assert case.appearance == look and stack.undo_text == "Colour the face"
    record = case.audit.records[-1]
    assert record["command"] == "SetAppearance" and record["action"] == "do"
    params = record["parameters"]
    assert params["appearance"] == look.to_state() and params["note"] == ARTISTIC_NOTE
    assert set(params["changed"]) == {"tone", "iris", "lips"}
    stack.undo()
    assert case.appearance is None
    stack.redo()
    assert case.appearance == look
    stack.push(SetAppearance(None))
    assert case.appearance is None and stack.undo_text == "Remove the face colours"
    stack.undo()
    assert case.appearance == look


def test_a_state_mapping_is_accepted_and_bad_values_refused_before_pushing() -> None:
    assert SetAppearance({"tone": "dark", "regions": {}, "iris": "grey"}).new == Appearance(
        tone="dark", iris="grey"
    )
    with pytest.raises(AppearanceError, match="unknown preset"):
        SetAppearance({"tone": "tan", "regions": {}, "iris": "grey"})
    case = Case(appearance=Appearance())
    with pytest.raises(CommandError, match="already has these colours"):
        CommandStack(case).push(SetAppearance(Appearance()))


def test_moves_of_one_region_merge_into_one_step() -> None:
    case = Case()
    stack = CommandStack(case)
    base = Appearance()
    for v in (0.3, 0.35, 0.4):
        stack.push(SetAppearance(base.with_colour("lips", Hsv(0.0, 0.5, v)), merge_key="lips"))
    assert len(stack) == 1 and case.appearance.colour("lips") == Hsv(0.0, 0.5, 0.4)
    # another region is another step; so is the same region after something else
    stack.push(
        SetAppearance(case.appearance.with_colour("brows", Hsv(0, 0, 0.2)), merge_key="brows")
    )
    stack.push(SetParameter("x", 1))
    stack.push(
        SetAppearance(case.appearance.with_colour("brows", Hsv(0, 0, 0.3)), merge_key="brows")
    )
    assert len(stack) == 4
    # every push is audited; undo takes the merged drag back in one step
    assert [r["action"] for r in case.audit.records].count("do") == 6
    for _ in range(3):
        stack.undo()
    assert case.appearance.colour("lips") == Hsv(0.0, 0.5, 0.4)
    stack.undo()
    assert case.appearance is None
    stack.redo()
    assert case.appearance.colour("lips") == Hsv(0.0, 0.5, 0.4)


def test_a_drag_back_to_where_it_began_stays_undoable() -> None:
    case = Case(appearance=Appearance())
    stack = CommandStack(case)
    start = case.appearance
    stack.push(SetAppearance(start.with_colour("cheeks", Hsv(0.1, 0.5, 0.5)), merge_key="cheeks"))
    stack.push(SetAppearance(start, merge_key="cheeks"))  # dragged back
    assert len(stack) == 1 and case.appearance == start
    stack.undo()
    stack.redo()  # the merged step changes nothing, and is not refused for it
    assert case.appearance == start
    # commands without a merge key never merge
    stack.push(SetAppearance(start.replaced(iris="grey")))
    stack.push(SetAppearance(start.replaced(iris="green")))
    assert len(stack) == 3
