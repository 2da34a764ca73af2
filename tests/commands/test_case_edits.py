"""Case-level commands: parameters, specimen, examiner, evidence."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.commands.case_edits import (
    AddEvidence,
    DeleteParameter,
    SetExaminer,
    SetNotes,
    SetParameter,
    SetSpecimen,
)
from workbench.commands.stack import CommandError, CommandStack
from workbench.core.mesh import Mesh
from workbench.model.case import Case, EvidenceConflictError
from workbench.model.evidence import EvidenceFile

SHA = "c" * 64


def test_set_parameter_json_values(case: Case, stack: CommandStack) -> None:
    stack.push(SetParameter("guides", {"nose": {"projection_mm": 1.5, "points": [1, 2]}}))
    assert case.parameters["guides"]["nose"]["points"] == (1, 2)
    with pytest.raises(ValueError, match="non-finite"):
        SetParameter("x", float("inf"))
    with pytest.raises(TypeError):
        SetParameter("x", {1, 2})
    with pytest.raises(CommandError):
        SetParameter("", 1)


def test_delete_parameter(case: Case, stack: CommandStack) -> None:
    stack.push(SetParameter("a", 1))
    stack.push(DeleteParameter("a"))
    assert "a" not in case.parameters
    with pytest.raises(CommandError, match="no parameter 'a'"):
        stack.push(DeleteParameter("a"))
    stack.undo()
    assert case.parameters["a"] == 1


def test_table_ids_only_for_table_keys() -> None:
    assert SetParameter("depth_table", "stephan_2013").table_ids() == ("stephan_2013",)
    assert SetParameter("growth_table_id", "g1").table_ids() == ("g1",)
    assert SetParameter("build", "slim").table_ids() == ()


def test_set_specimen_and_transform(case: Case, stack: CommandStack) -> None:
    mesh = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    transform = np.diag([1.0, 1.0, 1.0, 1.0])
    transform[0, 3] = 5.0
    stack.push(SetSpecimen(mesh, "mm", transform))
    assert case.specimen.mesh is mesh
    assert case.specimen.head_mesh.vertices[0].tolist() == [5, 0, 0]
    stack.undo()
    assert case.specimen.mesh is None
    with pytest.raises(ValueError, match="shape"):
        SetSpecimen(mesh, "mm", np.eye(3))
    with pytest.raises(ValueError, match="units"):
        SetSpecimen(mesh, "")
    params = SetSpecimen(mesh).parameters()
    assert params["mesh"]["n_vertices"] == 3
    assert len(params["mesh"]["sha256"]) == 64


def test_examiner_undo_restores_only_the_name(case: Case, stack: CommandStack) -> None:
    stack.push(SetExaminer("Dr. A"))
    case.replace("meta", case.meta.touched("2030-01-01T00:00:00.000+00:00"))  # a save
    stack.undo()
    assert case.meta.examiner == ""
    assert case.meta.modified.startswith("2030")
    stack.push(SetNotes("received sealed"))
    assert case.meta.notes == "received sealed"
    with pytest.raises(CommandError, match="text"):
        stack.push(SetExaminer(42))  # type: ignore[arg-type]


def test_add_evidence_undo_hides_but_retains(case: Case, stack: CommandStack) -> None:
    item = EvidenceFile("skull.ply", SHA, 100, "skull_mesh", "/evidence/skull.ply")
    stack.push(AddEvidence(item))
    assert case.evidence == (item,)
    stack.undo()
    assert case.evidence == ()
    assert case.retained_evidence == {"skull.ply": item}
    actions = [(r["action"], r["parameters"]["evidence"]["sha256"]) for r in case.audit.records]
    assert actions == [("do", SHA), ("undo", SHA)]
    stack.redo()
    assert case.evidence == (item,)


def test_add_evidence_refuses_duplicates_and_name_clashes(case: Case, stack: CommandStack) -> None:
    item = EvidenceFile("skull.ply", SHA, 100, "skull_mesh")
    stack.push(AddEvidence(item))
    with pytest.raises(CommandError, match="already has"):
        stack.push(AddEvidence(item))
    stack.undo()
    other = EvidenceFile("skull.ply", "d" * 64, 100, "skull_mesh")
    with pytest.raises(EvidenceConflictError, match="different file"):
        stack.push(AddEvidence(other))
    renamed = EvidenceFile(case.unused_evidence_name("skull.ply"), "d" * 64, 100, "skull_mesh")
    stack.push(AddEvidence(renamed))
    assert [e.name for e in case.evidence] == ["skull-2.ply"]
    with pytest.raises(CommandError):
        AddEvidence(None)
