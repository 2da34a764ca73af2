"""SetAgeStudy: the case's age study replaced on the one stack, undo/redo, audit records."""

from __future__ import annotations

import pytest

from workbench.commands.age_study import SetAgeStudy
from workbench.commands.stack import CommandError, CommandStack
from workbench.model.age_study import AgeStudy, AgeStudyError
from workbench.model.case import Case

FIRST = AgeStudy(source="reference:female", sex="female", from_age=30, target_ages=(12,))
SECOND = FIRST.replaced(target_ages=(5, 8), ethnicity="European")


def test_set_undo_redo_restore_each_value(case: Case, stack: CommandStack) -> None:
    seen: list[str] = []
    case.events.changed.connect(seen.append)
    stack.push(SetAgeStudy(FIRST))
    assert case.age_study is FIRST
    assert stack.undo_text == "Keep the age study"
    stack.push(SetAgeStudy(SECOND))
    assert case.age_study == SECOND
    stack.undo()
    assert case.age_study is FIRST
    stack.undo()
    assert case.age_study is None
    stack.redo()
    stack.redo()
    assert case.age_study == SECOND
    stack.push(SetAgeStudy(None))
    assert case.age_study is None and stack.undo_text == "Remove the age study"
    stack.undo()
    assert case.age_study == SECOND
    assert seen == ["age_study"] * 8


def test_a_state_mapping_is_accepted_and_bad_values_fail_before_the_push(
    case: Case, stack: CommandStack
) -> None:
    command = SetAgeStudy(FIRST.to_state())
    assert command.new == FIRST
    with pytest.raises(AgeStudyError, match="target age: 140 is not an age"):
        SetAgeStudy({**FIRST.to_state(), "target_ages": [140]})
    assert len(stack) == 0 and case.age_study is None
    stack.push(command)
    with pytest.raises(CommandError, match="already keeps this age study"):
        stack.push(SetAgeStudy(FIRST))
    assert len(stack) == 1


def test_audit_records_name_what_changed(case: Case, stack: CommandStack) -> None:
    stack.push(SetAgeStudy(FIRST))
    stack.push(SetAgeStudy(SECOND))
    stack.undo()
    records = list(case.audit.records)
    assert [r["action"] for r in records] == ["do", "do", "undo"]
    first, second, undo = records
    assert first["command"] == "SetAgeStudy"
    assert first["operation"] == "Keep the age study"
    assert first["parameters"]["changed"] == list(FIRST.to_state())
    assert first["parameters"]["age_study"] == FIRST.to_state()
    assert first["table_ids"] == ["facial_norms"]
    assert second["parameters"]["changed"] == ["target_ages", "ethnicity"]
    assert second["parameters"]["age_study"]["target_ages"] == [5.0, 8.0]
    assert undo["parameters"] == second["parameters"]
