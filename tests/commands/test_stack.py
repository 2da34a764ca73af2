"""CommandStack: undo/redo, merging, groups, gestures, dirty state and audit."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.commands.case_edits import SetExaminer, SetParameter
from workbench.commands.landmarks import MoveLandmark, PlaceLandmark
from workbench.commands.stack import Command, CommandError, CommandStack, MacroCommand
from workbench.core.errors import LandmarkError
from workbench.model.case import Case
from workbench.model.state import states_equal


def position(case: Case, code: str, surface: str = "skull") -> list[float]:
    return case.landmarks[surface][code].position.tolist()


# ---------------------------------------------------------------- basics
def test_push_undo_redo_and_texts(case: Case, stack: CommandStack) -> None:
    assert not stack.can_undo
    assert not stack.can_redo
    assert stack.undo_text == ""
    assert stack.redo_text == ""
    stack.push(PlaceLandmark("skull", "n", [1, 2, 3]))
    stack.push(SetParameter("build", "slim"))
    assert stack.undo_text == "Set build"
    assert len(stack) == 2
    stack.undo()
    assert stack.redo_text == "Set build"
    assert stack.undo_text == "Place skull landmark n"
    assert "build" not in case.parameters
    stack.redo()
    assert case.parameters["build"] == "slim"
    assert not stack.can_redo


def test_push_clears_redo(case: Case, stack: CommandStack) -> None:
    stack.push(SetParameter("a", 1))
    stack.push(SetParameter("b", 2))
    stack.undo()
    assert stack.can_redo
    stack.push(SetParameter("c", 3))
    assert not stack.can_redo
    assert dict(case.parameters) == {"a": 1, "c": 3}


def test_nothing_to_undo_or_redo_raises(stack: CommandStack) -> None:
    with pytest.raises(CommandError, match="nothing to undo"):
        stack.undo()
    with pytest.raises(CommandError, match="nothing to redo"):
        stack.redo()


def test_failed_push_changes_nothing(case: Case, stack: CommandStack) -> None:
    records: list[dict] = []
    stack.audit = records.append
    stack.push(SetParameter("a", 1))
    before = case.to_state()
    with pytest.raises(LandmarkError, match="no skull landmark"):
        stack.push(MoveLandmark("skull", "n", [0, 0, 0]))
    assert states_equal(case.to_state(), before)
    assert len(stack) == 1
    assert len(records) == 1


def test_clear_forgets_history_but_keeps_dirty_flag(case: Case, stack: CommandStack) -> None:
    stack.push(SetParameter("a", 1))
    stack.clear()
    assert not stack.can_undo
    assert stack.is_dirty
    assert case.parameters["a"] == 1
    stack.set_clean()
    stack.clear()
    assert not stack.is_dirty


def test_changed_signal_fires(stack: CommandStack) -> None:
    count = []
    stack.changed.connect(lambda: count.append(1))
    stack.push(SetParameter("a", 1))
    stack.undo()
    stack.redo()
    stack.set_clean()
    assert len(count) == 4


# ---------------------------------------------------------------- dirty flag
def test_dirty_flag_follows_clean_point(stack: CommandStack) -> None:
    assert not stack.is_dirty
    stack.push(SetParameter("a", 1))
    assert stack.is_dirty
    stack.set_clean()
    assert not stack.is_dirty
    stack.push(SetParameter("b", 2))
    assert stack.is_dirty
    stack.undo()
    assert not stack.is_dirty
    stack.undo()
    assert stack.is_dirty
    stack.redo()
    assert not stack.is_dirty


def test_clean_point_lost_when_its_redo_branch_is_dropped(stack: CommandStack) -> None:
    stack.push(SetParameter("a", 1))
    stack.set_clean()
    stack.undo()
    stack.push(SetParameter("b", 2))
    assert stack.is_dirty
    stack.undo()
    assert stack.is_dirty  # the saved state (a=1) cannot be reached any more


# ---------------------------------------------------------------- merging
def test_consecutive_moves_of_one_landmark_merge(case: Case, stack: CommandStack) -> None:
    stack.push(PlaceLandmark("skull", "n", [0, 0, 0]))
    for x in range(1, 6):
        stack.push(MoveLandmark("skull", "n", [x, 0, 0]))
    assert len(stack) == 2
    assert position(case, "n") == [5, 0, 0]
    stack.undo()
    assert position(case, "n") == [0, 0, 0]
    stack.redo()
    assert position(case, "n") == [5, 0, 0]


def test_moves_of_different_landmarks_do_not_merge(stack: CommandStack) -> None:
    stack.push(PlaceLandmark("skull", "n", [0, 0, 0]))
    stack.push(PlaceLandmark("skull", "g", [0, 0, 0]))
    stack.push(PlaceLandmark("skin", "g", [0, 0, 0]))
    stack.push(MoveLandmark("skull", "n", [1, 0, 0]))
    stack.push(MoveLandmark("skull", "g", [1, 0, 0]))
    stack.push(MoveLandmark("skin", "g", [1, 0, 0]))
    assert len(stack) == 6


def test_merge_window_closes_on_undo_and_save(case: Case, stack: CommandStack) -> None:
    stack.push(PlaceLandmark("skull", "n", [0, 0, 0]))
    stack.push(MoveLandmark("skull", "n", [1, 0, 0]))
    stack.set_clean()
    stack.push(MoveLandmark("skull", "n", [2, 0, 0]))
    assert len(stack) == 3
    assert stack.is_dirty
    stack.undo()
    assert not stack.is_dirty
    assert position(case, "n") == [1, 0, 0]
    stack.redo()
    stack.push(MoveLandmark("skull", "n", [3, 0, 0]))
    assert len(stack) == 4


def test_parameter_slider_merges(case: Case, stack: CommandStack) -> None:
    for value in (1.0, 1.5, 2.0):
        stack.push(SetParameter("nose_projection_mm", value))
    stack.push(SetParameter("other", 1))
    assert len(stack) == 2
    stack.undo()
    stack.undo()
    assert "nose_projection_mm" not in case.parameters


# ---------------------------------------------------------------- gestures
def test_gesture_is_one_step(case: Case, stack: CommandStack) -> None:
    stack.push(PlaceLandmark("skull", "n", [0, 0, 0]))
    before = case.to_state()
    stack.begin_gesture("Drag nasion")
    assert not stack.can_undo
    for x in np.linspace(0, 10, 20):
        stack.push(MoveLandmark("skull", "n", [x, 1, 0]))
    stack.push(PlaceLandmark("skull", "g", [0, 5, 0]))
    stack.commit_gesture()
    after = case.to_state()
    assert len(stack) == 2
    assert stack.undo_text == "Drag nasion"
    stack.undo()
    assert states_equal(case.to_state(), before)
    stack.redo()
    assert states_equal(case.to_state(), after)


def test_abort_gesture_restores_state(case: Case, stack: CommandStack) -> None:
    stack.push(PlaceLandmark("skull", "n", [0, 0, 0]))
    before = case.to_state()
    stack.begin_gesture("Drag nasion")
    stack.push(MoveLandmark("skull", "n", [1, 0, 0]))
    stack.push(SetParameter("a", 1))
    stack.abort_gesture()
    assert states_equal(case.to_state(), before)
    assert len(stack) == 1
    assert stack.can_undo


def test_gesture_errors(stack: CommandStack) -> None:
    with pytest.raises(CommandError, match="no gesture"):
        stack.commit_gesture()
    with pytest.raises(CommandError, match="no gesture"):
        stack.abort_gesture()
    stack.push(SetParameter("a", 1))
    stack.begin_gesture("drag")
    with pytest.raises(CommandError, match="already"):
        stack.begin_gesture("again")
    with pytest.raises(CommandError, match="gesture is in progress"):
        stack.undo()
    stack.commit_gesture()
    assert len(stack) == 1  # empty gesture adds no step


# ---------------------------------------------------------------- groups
def test_group_is_one_step(case: Case, stack: CommandStack) -> None:
    before = case.to_state()
    with stack.group("Place from table"):
        for code in ("n", "g", "pg"):
            stack.push(PlaceLandmark("skull", code, [1, 2, 3]))
        with stack.group("inner"):
            stack.push(SetParameter("table", "t1"))
    assert len(stack) == 1
    assert stack.undo_text == "Place from table"
    stack.undo()
    assert states_equal(case.to_state(), before)
    stack.redo()
    assert case.landmarks["skull"].codes == ("n", "g", "pg")
    assert case.parameters["table"] == "t1"


def test_group_rolls_back_on_exception(case: Case, stack: CommandStack) -> None:
    stack.push(SetParameter("keep", 1))
    before = case.to_state()
    with pytest.raises(LandmarkError), stack.group("broken"):
        stack.push(PlaceLandmark("skull", "n", [1, 2, 3]))
        stack.push(SetParameter("keep", 2))
        stack.push(MoveLandmark("skull", "zz", [0, 0, 0]))  # no such landmark
    assert states_equal(case.to_state(), before)
    assert len(stack) == 1
    assert stack.undo_text == "Set keep"


def test_group_rolls_back_on_any_exception(case: Case, stack: CommandStack) -> None:
    before = case.to_state()
    with pytest.raises(RuntimeError, match="boom"), stack.group("g"):
        stack.push(SetParameter("a", 1))
        raise RuntimeError("boom")
    assert states_equal(case.to_state(), before)
    assert len(stack) == 0


def test_gesture_left_open_in_group_is_an_error(case: Case, stack: CommandStack) -> None:
    before = case.to_state()
    with pytest.raises(CommandError, match="left open"), stack.group("g"):
        stack.push(SetParameter("a", 1))
        stack.begin_gesture("drag")
        stack.push(SetParameter("b", 1))
    assert states_equal(case.to_state(), before)
    assert not stack.in_gesture


def test_empty_group_adds_nothing(stack: CommandStack) -> None:
    with stack.group("nothing"):
        pass
    assert len(stack) == 0
    assert not stack.is_dirty


# ---------------------------------------------------------------- audit
def test_audit_records_do_undo_redo(case: Case, stack: CommandStack) -> None:
    stack.push(SetExaminer("Dr. Who"))
    stack.push(SetParameter("depth_table", "stephan_2013"))
    stack.undo()
    stack.redo()
    records = case.audit.records
    assert [r["action"] for r in records] == ["do", "do", "undo", "redo"]
    assert records[1]["operation"] == "Set depth_table"
    assert records[1]["parameters"] == {"key": "depth_table", "value": "stephan_2013"}
    assert records[1]["table_ids"] == ["stephan_2013"]
    assert records[1]["examiner"] == "Dr. Who"
    assert records[1]["time"]


def test_custom_audit_hook_and_group_records(case: Case) -> None:
    records: list[dict] = []
    stack = CommandStack(case, audit=records.append)
    with stack.group("Two"):
        stack.push(SetParameter("a", 1))
        assert records == []  # audited on commit
        stack.push(SetParameter("b", 2))
    assert len(records) == 1
    assert records[0]["operation"] == "Two"
    assert [c["label"] for c in records[0]["parameters"]["commands"]] == ["Set a", "Set b"]
    stack.begin_gesture("drag")
    stack.push(SetParameter("c", 3))
    stack.abort_gesture()
    assert records[-1]["action"] == "abort"
    assert records[-1]["parameters"]["reason"] == "aborted"
    assert len(case.audit) == 0


def test_custom_command_subclass() -> None:
    class Bump(Command):
        def do(self, case: Case) -> None:
            case.replace("parameters", {"n": case.parameters.get("n", 0) + 1})

        def undo(self, case: Case) -> None:
            case.replace("parameters", {"n": case.parameters["n"] - 1})

    case = Case()
    stack = CommandStack(case)
    stack.push(Bump())
    stack.push(Bump(label="Bump again"))
    assert case.parameters["n"] == 2
    assert stack.undo_text == "Bump again"
    stack.undo()
    assert case.parameters["n"] == 1
    assert Bump().label == "Bump"
    assert Bump().parameters() == {}
    assert isinstance(MacroCommand(label="m"), Command)
