"""The undoable command on the case's age-progression study (:mod:`workbench.model.age_study`).

:class:`SetAgeStudy` replaces the part ``age_study`` (an
:class:`~workbench.model.age_study.AgeStudy`, or ``None``: no study) and
keeps the previous value by reference for undo.  Its audit record names the
fields that changed and carries the new study (ages in years).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from workbench.commands.case_edits import ReplacePartCommand
from workbench.commands.stack import CommandError
from workbench.model.age_study import AgeStudy
from workbench.model.case import Case


@dataclass(eq=False)
class SetAgeStudy(ReplacePartCommand):
    """Keep ``new`` as the case's age study (a state mapping is accepted), or remove it (None).

    Raises
    ------
    AgeStudyError
        When built with invalid settings (nothing is pushed).
    CommandError
        When ``new`` equals the current study (nothing would change).
    """

    part: ClassVar[str] = "age_study"
    new: AgeStudy | Mapping[str, Any] | None = None
    _changed: tuple[str, ...] = field(default=(), init=False, repr=False)

    def __post_init__(self) -> None:
        if self.new is not None and not isinstance(self.new, AgeStudy):
            self.new = AgeStudy.from_state(self.new)  # raises for bad values
        super().__post_init__()

    @property
    def study(self) -> AgeStudy | None:
        return self.new  # type: ignore[return-value]  # made an AgeStudy in __post_init__

    def default_label(self) -> str:
        return "Remove the age study" if self.new is None else "Keep the age study"

    def apply(self, case: Case) -> Any:
        before, new = case.age_study, self.study
        if new == before:
            raise CommandError("the case already keeps this age study")
        if new is None:
            self._changed = () if before is None else before.changed_fields(None)
        else:
            self._changed = new.changed_fields(before)
        return new

    def table_ids(self) -> tuple[str, ...]:
        return () if self.study is None else (self.study.norms,)

    def parameters(self) -> dict[str, Any]:
        study = self.study
        return {
            "changed": list(self._changed),
            "age_study": None if study is None else study.to_state(),
        }
