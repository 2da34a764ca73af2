"""Commands that edit the case as a whole: parameters, specimen, meta, evidence.

Evidence and undo
-----------------
:class:`AddEvidence` is undoable, but undo only *hides the reference*: the
file disappears from ``case.evidence`` while ``case.retained_evidence`` keeps
it, so the case file goes on storing its bytes (verbatim, under
``evidence/<name>``) and the audit log keeps the ``do`` and ``undo`` records
naming its sha256.  Nothing ever deletes evidence bytes from a case file:
for forensic work every file that was ever part of the case must stay
available to show how a result was reached.  Re-adding the same file is a
no-op for storage; a *different* file under a used name is refused (see
:meth:`~workbench.model.case.Case.unused_evidence_name`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from workbench.commands.stack import Command, CommandError, to_jsonable
from workbench.core.mesh import Mesh
from workbench.model.case import Case
from workbench.model.evidence import EvidenceFile
from workbench.model.specimen import Specimen
from workbench.model.state import freeze_json, thaw_json


@dataclass(eq=False)
class ReplacePartCommand(Command):
    """Base: replace part :attr:`part` by :meth:`apply`'s value; undo restores the old value."""

    part: ClassVar[str] = ""
    _before: Any = field(default=None, init=False, repr=False)

    def apply(self, case: Case) -> Any:
        raise NotImplementedError

    def do(self, case: Case) -> None:
        new = self.apply(case)
        before = case.part(self.part)
        case.replace(self.part, new)
        self._before = before

    def undo(self, case: Case) -> None:
        case.replace(self.part, self._before)


def _is_table_key(key: str) -> bool:
    return key.endswith(("_table", "table_id"))


@dataclass(eq=False)
class SetParameter(ReplacePartCommand):
    """Set ``parameters[key] = value`` (any JSON value).

    Consecutive sets of the same key merge (a slider drag is one step).  Keys
    ending in ``_table`` or ``table_id`` name a data table; their string
    value is reported in the audit record's ``table_ids``.
    """

    part: ClassVar[str] = "parameters"
    key: str = ""
    value: Any = None

    def __post_init__(self) -> None:
        if not isinstance(self.key, str) or not self.key:
            raise CommandError("a parameter needs a non-empty string key")
        self.value = freeze_json(self.value, f"parameter {self.key!r}")
        super().__post_init__()

    def default_label(self) -> str:
        return f"Set {self.key}"

    def apply(self, case: Case) -> Any:
        return MappingProxyType({**case.parameters, self.key: self.value})

    def merge_with(self, other: Command) -> bool:
        if isinstance(other, SetParameter) and other.key == self.key:
            self.value = other.value
            return True
        return False

    def parameters(self) -> dict[str, Any]:
        return {"key": self.key, "value": thaw_json(self.value)}

    def table_ids(self) -> tuple[str, ...]:
        if _is_table_key(self.key) and isinstance(self.value, str):
            return (self.value,)
        return ()


@dataclass(eq=False)
class DeleteParameter(ReplacePartCommand):
    """Remove ``parameters[key]``."""

    part: ClassVar[str] = "parameters"
    key: str = ""

    def default_label(self) -> str:
        return f"Clear {self.key}"

    def apply(self, case: Case) -> Any:
        if self.key not in case.parameters:
            raise CommandError(f"there is no parameter {self.key!r}")
        return MappingProxyType({k: v for k, v in case.parameters.items() if k != self.key})


@dataclass(eq=False)
class SetSpecimen(ReplacePartCommand):
    """Replace the working mesh, its units and the input-to-head transform.

    Parameters
    ----------
    mesh : Mesh or None
        Working skull mesh (input frame).
    units : str
        Units of ``mesh``.
    input_to_head : (4, 4) float64 or None
        Input frame to head frame.
    """

    part: ClassVar[str] = "specimen"
    mesh: Mesh | None = None
    units: str = "mm"
    input_to_head: np.ndarray | None = None

    def __post_init__(self) -> None:
        # Validate now, so a bad value fails when the command is built.
        self._specimen = Specimen(self.mesh, self.units, self.input_to_head)
        self.input_to_head = self._specimen.input_to_head
        super().__post_init__()

    def default_label(self) -> str:
        return "Set specimen" if self.mesh is not None else "Clear specimen"

    def apply(self, case: Case) -> Any:
        return self._specimen


@dataclass(eq=False)
class _SetMetaField(Command):
    """Base: set one text field of ``case.meta``; undo restores only that field."""

    field_name: ClassVar[str] = ""
    _old: str | None = field(default=None, init=False, repr=False)

    def _new_value(self) -> str:
        raise NotImplementedError

    def do(self, case: Case) -> None:
        value = self._new_value()
        if not isinstance(value, str):
            raise CommandError(f"{self.field_name} must be text")
        old = getattr(case.meta, self.field_name)
        case.replace("meta", replace(case.meta, **{self.field_name: value}))
        self._old = old

    def undo(self, case: Case) -> None:
        if self._old is None:
            raise RuntimeError(f"{self.label!r} was undone before it was done")
        case.replace("meta", replace(case.meta, **{self.field_name: self._old}))


@dataclass(eq=False)
class SetExaminer(_SetMetaField):
    """Set the examiner's name (undo restores only the name, not ``modified``)."""

    field_name: ClassVar[str] = "examiner"
    examiner: str = ""

    def default_label(self) -> str:
        return "Set examiner"

    def _new_value(self) -> str:
        return self.examiner


@dataclass(eq=False)
class SetNotes(_SetMetaField):
    """Replace the case notes."""

    field_name: ClassVar[str] = "notes"
    notes: str = ""

    def default_label(self) -> str:
        return "Edit case notes"

    def _new_value(self) -> str:
        return self.notes


@dataclass(eq=False)
class SetCaseDetails(Command):
    """Set the examiner's name and the case notes as one undo step (the window's
    File ▸ Case details…); undo restores both and nothing else of ``case.meta``
    (not ``modified``), as :class:`SetExaminer` and :class:`SetNotes` do for one."""

    examiner: str = ""
    notes: str = ""
    _old: tuple[str, str] | None = field(default=None, init=False, repr=False)

    def default_label(self) -> str:
        return "Edit case details"

    def do(self, case: Case) -> None:
        for name in ("examiner", "notes"):
            if not isinstance(getattr(self, name), str):
                raise CommandError(f"{name} must be text")
        old = (case.meta.examiner, case.meta.notes)
        case.replace("meta", replace(case.meta, examiner=self.examiner, notes=self.notes))
        self._old = old

    def undo(self, case: Case) -> None:
        if self._old is None:
            raise RuntimeError(f"{self.label!r} was undone before it was done")
        examiner, notes = self._old
        case.replace("meta", replace(case.meta, examiner=examiner, notes=notes))


@dataclass(eq=False)
class AddEvidence(ReplacePartCommand):
    """Reference an original evidence file from the case (see the module docstring)."""

    part: ClassVar[str] = "evidence"
    evidence: EvidenceFile | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.evidence, EvidenceFile):
            raise CommandError("AddEvidence needs an EvidenceFile")
        super().__post_init__()

    def default_label(self) -> str:
        if self.evidence is None:  # refused by __post_init__
            raise CommandError("AddEvidence needs an EvidenceFile")
        return f"Add evidence {self.evidence.name}"

    def apply(self, case: Case) -> Any:
        item = self.evidence
        assert item is not None
        if any(e.name == item.name for e in case.evidence):
            raise CommandError(f"the case already has an evidence file named {item.name!r}")
        return (*case.evidence, item)

    def parameters(self) -> dict[str, Any]:
        return {"evidence": to_jsonable(self.evidence)}
