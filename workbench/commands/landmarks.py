"""Landmark commands: place, move, change status, delete, replace a whole set.

Each command replaces the :class:`~workbench.core.landmarks.LandmarkSet` of
one surface and keeps the previous set by reference for undo.  Positions are
in mm in the specimen's input frame (see :mod:`workbench.model.case`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from workbench.commands.stack import Command
from workbench.core.errors import LandmarkError
from workbench.core.landmarks import DEFINED_STATUSES, STATUSES, SURFACES, Landmark, LandmarkSet
from workbench.model.case import Case


def _position(value: Any) -> np.ndarray:
    """``(3,)`` read-only float64 position in mm; raises for non-finite values."""
    position = np.array(value, dtype=np.float64).reshape(-1)
    if position.shape != (3,) or not np.isfinite(position).all():
        raise LandmarkError(f"a landmark position needs 3 finite numbers (mm), got {value!r}")
    position.setflags(write=False)
    return position


@dataclass(eq=False)
class LandmarkCommand(Command):
    """Base: replaces the landmark set of ``surface``; ``apply`` computes the new set."""

    surface: str
    _before: LandmarkSet | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.surface not in SURFACES:
            raise LandmarkError(f"surface must be one of {SURFACES}, got {self.surface!r}")
        super().__post_init__()

    def apply(self, current: LandmarkSet) -> LandmarkSet:
        raise NotImplementedError

    def do(self, case: Case) -> None:
        current = case.landmarks[self.surface]
        new = self.apply(current)
        self._before = current
        case.set_landmark_set(new)

    def undo(self, case: Case) -> None:
        if self._before is None:
            raise RuntimeError(f"{self.label!r} was undone before it was done")
        case.set_landmark_set(self._before)


@dataclass(eq=False)
class _CodeCommand(LandmarkCommand):
    code: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.code, str) or not self.code:
            raise LandmarkError("a landmark code is required")
        super().__post_init__()

    def _existing(self, current: LandmarkSet) -> Landmark:
        landmark = current.get(self.code)
        if landmark is None:
            raise LandmarkError(f"there is no {self.surface} landmark {self.code!r}")
        return landmark


@dataclass(eq=False)
class PlaceLandmark(_CodeCommand):
    """Put landmark ``code`` at ``position`` (mm) with status ``placed``.

    Adds the landmark or replaces an existing one (keeping its description).
    """

    position: Any = None

    def __post_init__(self) -> None:
        self.position = _position(self.position)
        super().__post_init__()

    def default_label(self) -> str:
        return f"Place {self.surface} landmark {self.code}"

    def apply(self, current: LandmarkSet) -> LandmarkSet:
        old = current.get(self.code)
        description = old.description if old is not None else ""
        landmark = Landmark(self.code, self.position, "placed", 1.0, description)
        return current.with_landmark(landmark)


@dataclass(eq=False)
class MoveLandmark(_CodeCommand):
    """Move an existing defined landmark to ``position`` (mm); it becomes ``placed``.

    Consecutive moves of the same landmark with the same label merge into one
    undo step (a drag); a differently labelled move (e.g. ``"Snap g to ..."``)
    stays a step of its own.
    """

    position: Any = None

    def __post_init__(self) -> None:
        self.position = _position(self.position)
        super().__post_init__()

    def default_label(self) -> str:
        return f"Move {self.surface} landmark {self.code}"

    def apply(self, current: LandmarkSet) -> LandmarkSet:
        landmark = self._existing(current)
        if not landmark.is_defined:
            raise LandmarkError(
                f"{self.surface} landmark {self.code!r} is {landmark.status}; place it first"
            )
        return current.with_landmark(landmark.moved(self.position, "placed"))

    def merge_with(self, other: Command) -> bool:
        if not isinstance(other, MoveLandmark):
            return False
        if (other.surface, other.code, other.label) != (self.surface, self.code, self.label):
            return False
        self.position = other.position
        return True


@dataclass(eq=False)
class SetLandmarkStatus(_CodeCommand):
    """Change a landmark's status, e.g. mark it ``absent`` (damaged anatomy).

    ``absent`` and ``missing`` clear the position (and may create the entry);
    ``placed`` / ``suggested`` need a landmark that already has a position
    (e.g. confirming a suggestion).
    """

    status: str = "absent"

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise LandmarkError(f"status must be one of {STATUSES}, got {self.status!r}")
        super().__post_init__()

    def default_label(self) -> str:
        return f"Mark {self.surface} landmark {self.code} {self.status}"

    def apply(self, current: LandmarkSet) -> LandmarkSet:
        old = current.get(self.code)
        if self.status in DEFINED_STATUSES:
            if old is None or not old.is_defined:
                raise LandmarkError(
                    f"{self.surface} landmark {self.code!r} has no position to mark {self.status}"
                )
            confidence = 1.0 if self.status == "placed" else old.confidence
            new = Landmark(self.code, old.position, self.status, confidence, old.description)
        else:
            description = old.description if old is not None else ""
            new = Landmark(self.code, np.full(3, np.nan), self.status, 1.0, description)
        return current.with_landmark(new)


@dataclass(eq=False)
class DeleteLandmark(_CodeCommand):
    """Remove landmark ``code`` from the set of ``surface``."""

    def default_label(self) -> str:
        return f"Delete {self.surface} landmark {self.code}"

    def apply(self, current: LandmarkSet) -> LandmarkSet:
        self._existing(current)
        return current.without(self.code)


@dataclass(eq=False, init=False)
class ReplaceLandmarkSet(LandmarkCommand):
    """Replace the whole set of ``surface`` (accepting suggestions, importing a file).

    Parameters
    ----------
    surface : str
    new_set : LandmarkSet
        Must be a set on ``surface``.
    label : str
        Edit-menu text, e.g. ``"Import landmarks from skull.mrk.json"``.
    """

    new_set: LandmarkSet = field(default_factory=lambda: LandmarkSet("skull"))

    def __init__(self, surface: str, new_set: LandmarkSet, label: str = "") -> None:
        self.surface = surface
        self.new_set = new_set
        self.label = label
        self._before = None
        self.__post_init__()

    def __post_init__(self) -> None:
        if not isinstance(self.new_set, LandmarkSet):
            raise LandmarkError("new_set must be a LandmarkSet")
        if self.new_set.surface != self.surface:
            raise LandmarkError(
                f"cannot put a {self.new_set.surface} landmark set on the {self.surface} surface"
            )
        super().__post_init__()

    def default_label(self) -> str:
        return f"Replace {self.surface} landmarks"

    def apply(self, current: LandmarkSet) -> LandmarkSet:
        return self.new_set
