"""Undoable commands on the reconstruction settings: dowels, orientation, guides.

Each command replaces one typed part of the case (see
:mod:`workbench.model.reconstruction_setup`) and keeps the previous value by
reference for undo.  Values are validated when the command is built, so a
bad value fails before anything is pushed; :meth:`do` re-checks against the
current case.  Depths are mm; orientation vectors are directions in the
skull file's coordinates; guide values are mm in the head frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any, ClassVar

from workbench.commands.case_edits import ReplacePartCommand
from workbench.commands.stack import Command, CommandError, to_jsonable
from workbench.model.case import Case
from workbench.model.reconstruction_setup import (
    DowelSettings,
    GuideList,
    Orientation,
    build_text,
)

_FIELD_LABELS = {
    "table": "depth table",
    "sex": "sex",
    "build": "build",
    "overrides": "depth overrides",
    "excluded": "excluded dowels",
    "tissue_model": "tissue model",
    "region_factors": "region factors",
    "jaw": "jaw position",
}


@dataclass(eq=False)
class SetDowelSettings(ReplacePartCommand):
    """Change some fields of the dowel settings (the fields left ``None`` keep their value).

    Consecutive commands changing the same fields merge (a slider drag or a
    combo box run through is one undo step).  A table id is reported in the
    audit record's ``table_ids``.
    """

    part: ClassVar[str] = "dowels"
    table: str | None = None
    sex: str | None = None
    build: str | float | None = None
    overrides: Mapping[str, float] | None = None
    excluded: Sequence[str] | None = None
    tissue_model: str | None = None
    region_factors: Mapping[str, float] | None = None
    jaw: str | None = None

    def __post_init__(self) -> None:
        if not self.changes():
            raise CommandError("SetDowelSettings needs at least one field to change")
        checked = DowelSettings().replaced(**self.changes())  # raises for bad values
        for name in self.changes():  # keep the normalised, read-only values
            setattr(self, name, getattr(checked, name))
        super().__post_init__()

    def changes(self) -> dict[str, Any]:
        """``{field: new value}`` of the fields this command sets."""
        return {
            f.name: getattr(self, f.name)
            for f in fields(DowelSettings)
            if getattr(self, f.name) is not None
        }

    def default_label(self) -> str:
        changes = self.changes()
        if list(changes) == ["build"]:
            return f"Set build {build_text(changes['build'])}"
        if list(changes) == ["table"]:
            return "Choose depth table"
        return "Set " + ", ".join(_FIELD_LABELS[name] for name in changes)

    def apply(self, case: Case) -> Any:
        return case.dowels.replaced(**self.changes())

    def merge_with(self, other: Command) -> bool:
        if isinstance(other, SetDowelSettings) and other.changes().keys() == self.changes().keys():
            for name, value in other.changes().items():
                setattr(self, name, value)
            self.label = other.label
            return True
        return False

    def parameters(self) -> dict[str, Any]:
        return {name: to_jsonable(value) for name, value in self.changes().items()}

    def table_ids(self) -> tuple[str, ...]:
        return (self.table,) if self.table is not None else ()


@dataclass(eq=False)
class SetDepthOverride(ReplacePartCommand):
    """Set one dowel's depth by hand (mm), or go back to the table (``depth_mm=None``).

    Consecutive overrides of the same code merge (typing a depth).
    """

    part: ClassVar[str] = "dowels"
    code: str = ""
    depth_mm: float | None = None

    def __post_init__(self) -> None:
        checked = DowelSettings().with_override(self.code, self.depth_mm)  # raises if bad
        self.code = self.code.strip()
        self.depth_mm = checked.overrides.get(self.code)
        super().__post_init__()

    def default_label(self) -> str:
        if self.depth_mm is None:
            return f"Use the table depth for {self.code}"
        return f"Set depth of {self.code} to {self.depth_mm:.1f} mm"

    def apply(self, case: Case) -> Any:
        if self.depth_mm is None and self.code not in case.dowels.overrides:
            raise CommandError(f"the depth of {self.code} is not overridden")
        return case.dowels.with_override(self.code, self.depth_mm)

    def merge_with(self, other: Command) -> bool:
        if (
            isinstance(other, SetDepthOverride)
            and other.code == self.code
            and other.depth_mm is not None
            and self.depth_mm is not None
        ):
            self.depth_mm = other.depth_mm
            self.label = other.label
            return True
        return False


@dataclass(eq=False)
class SetDowelExclusion(ReplacePartCommand):
    """Switch one dowel off (``excluded=True``) or back on."""

    part: ClassVar[str] = "dowels"
    code: str = ""
    excluded: bool = True

    def __post_init__(self) -> None:
        DowelSettings().with_exclusion(self.code, True)  # raises for a bad code
        self.code = self.code.strip()
        self.excluded = bool(self.excluded)
        super().__post_init__()

    def default_label(self) -> str:
        return f"{'Exclude' if self.excluded else 'Use'} dowel {self.code}"

    def apply(self, case: Case) -> Any:
        return case.dowels.with_exclusion(self.code, self.excluded)


@dataclass(eq=False)
class SetOrientation(ReplacePartCommand):
    """Set the skull file's face and up directions, or ``None``: find them from the bone."""

    part: ClassVar[str] = "orientation"
    orientation: Orientation | None = None

    def __post_init__(self) -> None:
        if self.orientation is not None and not isinstance(self.orientation, Orientation):
            self.orientation = Orientation.from_hint(self.orientation)  # a (a, s[, l]) tuple
        super().__post_init__()

    def default_label(self) -> str:
        return "Automatic orientation" if self.orientation is None else "Set skull orientation"

    def apply(self, case: Case) -> Any:
        return self.orientation

    def parameters(self) -> dict[str, Any]:
        o = self.orientation
        return {"orientation": None if o is None else o.to_state()}


@dataclass(eq=False)
class SetGuides(ReplacePartCommand):
    """Store the guide list (``guides_to_json`` layout), or ``None``: compute it from the skull."""

    part: ClassVar[str] = "guides"
    guides: GuideList | Sequence[Mapping[str, Any]] | None = None

    def __post_init__(self) -> None:
        if self.guides is not None and not isinstance(self.guides, GuideList):
            self.guides = GuideList(tuple(self.guides))
        super().__post_init__()

    def default_label(self) -> str:
        return "Recompute guides" if self.guides is None else "Set guides"

    def apply(self, case: Case) -> Any:
        return self.guides

    def parameters(self) -> dict[str, Any]:
        g = self.guides
        return {"guides": None if g is None else g.to_state()}  # type: ignore[union-attr]
