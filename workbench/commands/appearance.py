"""The undoable command on the colours chosen for the face (:mod:`workbench.model.appearance`).

:class:`SetAppearance` replaces the part ``appearance`` (an
:class:`~workbench.model.appearance.Appearance`, or ``None``: no colouring
chosen) and keeps the previous value by reference for undo.  Its audit
record names what changed (``tone``, ``iris`` or region names), carries the
new colours and says they are an artistic choice, not evidence.

Commands built with the same non-empty ``merge_key`` (the Appearance dock
uses the region's name) merge while pushed one after another, so one drag
of a region's hue, saturation or value sliders is one undo step.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

from workbench.commands.case_edits import ReplacePartCommand
from workbench.commands.stack import Command, CommandError
from workbench.model.appearance import ARTISTIC_NOTE, Appearance
from workbench.model.case import Case


@dataclass(eq=False)
class SetAppearance(ReplacePartCommand):
    """Colour the face with ``new`` (a state mapping is accepted), or drop the colours (None).

    Raises
    ------
    AppearanceError
        When built with invalid colours (nothing is pushed).
    CommandError
        When ``new`` equals the current colours (nothing would change).
    """

    part: ClassVar[str] = "appearance"
    new: Appearance | Mapping[str, Any] | None = None
    merge_key: str = ""
    _changed: tuple[str, ...] = field(default=(), init=False, repr=False)
    _merged: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.new is not None and not isinstance(self.new, Appearance):
            self.new = Appearance.from_state(self.new)  # raises for bad values
        super().__post_init__()

    @property
    def appearance(self) -> Appearance | None:
        return self.new  # type: ignore[return-value]  # made an Appearance in __post_init__

    def default_label(self) -> str:
        if self.new is None:
            return "Remove the face colours"
        if self.merge_key:
            return f"Colour the face: {self.merge_key}"
        return "Colour the face"

    def apply(self, case: Case) -> Any:
        before, new = case.appearance, self.appearance
        if new == before and not self._merged:
            raise CommandError("the face already has these colours")
        if new is None:
            self._changed = () if before is None else before.changed_fields(None)
        else:
            self._changed = new.changed_fields(before)
        return new

    def merge_with(self, other: Command) -> bool:
        if (
            isinstance(other, SetAppearance)
            and self.merge_key
            and other.merge_key == self.merge_key
            and other.new is not None
        ):
            self.new = other.new
            self._changed = tuple(dict.fromkeys((*self._changed, *other._changed)))
            self._merged = True  # a drag that ends where it began is still one step to undo
            return True
        return False

    def parameters(self) -> dict[str, Any]:
        look = self.appearance
        return {
            "changed": list(self._changed),
            "appearance": None if look is None else look.to_state(),
            "note": ARTISTIC_NOTE,
        }
