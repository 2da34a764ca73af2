"""Landmark sets: coded 3-D points on one surface (skin or skull).

Codes
-----
One code system is used everywhere (see ``data_tables/landmarks/catalogue.csv``):
skin landmarks in Farkas' anthropometric notation, skull landmarks in the
craniometric / Caple & Stephan (2016) notation.  A landmark is identified by
``(surface, code)``; some abbreviations (``n``, ``g``, ``pg``, ``zy_l`` ...)
exist on both surfaces, as in the literature, and the surface tells them
apart.  Bilateral landmarks carry ``_l`` or ``_r`` for the subject's left or
right side.

Units and frame
---------------
Positions are in millimetres in the frame of the mesh they were placed on.
An undefined point (status ``absent`` or ``missing``) has NaN coordinates.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field

import numpy as np

SURFACES = ("skin", "skull")

#: Status of one landmark.
#: ``placed``: put there by a person; ``suggested``: proposed by an algorithm,
#: not yet confirmed; ``absent``: the anatomy is missing or damaged (the user
#: or the algorithm says it cannot be placed); ``missing``: not placed yet.
STATUSES = ("placed", "suggested", "absent", "missing")
DEFINED_STATUSES = ("placed", "suggested")


@dataclass(frozen=True)
class Landmark:
    """One coded point.

    Parameters
    ----------
    code : str
        Catalogue code, e.g. ``"prn"`` or ``"zy_l"``.
    position : (3,) float64
        mm; NaN when the status is not a defined one.
    status : str
        One of :data:`STATUSES`.
    confidence : float
        0..1, for suggested points (1 for placed points).
    description : str
        Free text kept with the point (exchanged via ``.mrk.json``).
    """

    code: str
    position: np.ndarray
    status: str = "placed"
    confidence: float = 1.0
    description: str = ""

    def __post_init__(self) -> None:
        pos = np.array(self.position, dtype=np.float64).reshape(3)
        if self.status not in STATUSES:
            raise ValueError(f"landmark {self.code!r}: unknown status {self.status!r}")
        if self.status in DEFINED_STATUSES and not np.isfinite(pos).all():
            raise ValueError(f"landmark {self.code!r} is {self.status} but has no finite position")
        if self.status not in DEFINED_STATUSES:
            pos = np.full(3, np.nan)
        pos.setflags(write=False)
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "confidence", float(self.confidence))

    @property
    def is_defined(self) -> bool:
        return self.status in DEFINED_STATUSES

    def moved(self, position: np.ndarray, status: str = "placed") -> Landmark:
        return Landmark(
            self.code,
            position,
            status,
            1.0 if status == "placed" else self.confidence,
            self.description,
        )

    def equals(self, other: Landmark) -> bool:
        return (
            self.code == other.code
            and self.status == other.status
            and self.description == other.description
            and self.confidence == other.confidence
            and np.array_equal(self.position, other.position, equal_nan=True)
        )


@dataclass(frozen=True)
class LandmarkSet:
    """An ordered, immutable collection of landmarks on one surface.

    Operations return new sets (``with_landmark``, ``without``), so undo can
    keep the previous set by reference.
    """

    surface: str
    landmarks: tuple[Landmark, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if self.surface not in SURFACES:
            raise ValueError(f"surface must be one of {SURFACES}, got {self.surface!r}")
        object.__setattr__(self, "landmarks", tuple(self.landmarks))
        seen: set[str] = set()
        dups: list[str] = []
        for lm in self.landmarks:
            if lm.code in seen:
                dups.append(lm.code)
            seen.add(lm.code)
        if dups:
            raise ValueError(f"duplicate landmark codes in {self.surface} set: {', '.join(dups)}")

    # -------------------------------------------------------------- access
    def __len__(self) -> int:
        return len(self.landmarks)

    def __iter__(self) -> Iterator[Landmark]:
        return iter(self.landmarks)

    def __contains__(self, code: object) -> bool:
        return any(lm.code == code for lm in self.landmarks)

    def __getitem__(self, code: str) -> Landmark:
        for lm in self.landmarks:
            if lm.code == code:
                return lm
        raise KeyError(f"no {self.surface} landmark {code!r}")

    def get(self, code: str) -> Landmark | None:
        return next((lm for lm in self.landmarks if lm.code == code), None)

    @property
    def codes(self) -> tuple[str, ...]:
        return tuple(lm.code for lm in self.landmarks)

    @property
    def positions(self) -> np.ndarray:
        """``(n, 3)`` float64 mm, NaN rows for undefined points."""
        if not self.landmarks:
            return np.zeros((0, 3))
        return np.stack([lm.position for lm in self.landmarks])

    def defined(self) -> LandmarkSet:
        """Only the points with a position (placed or suggested)."""
        return LandmarkSet(self.surface, tuple(lm for lm in self.landmarks if lm.is_defined))

    def positions_of(self, codes: Iterable[str]) -> np.ndarray:
        """``(k, 3)`` positions for ``codes``; raises naming every code that is missing."""
        codes = list(codes)
        lookup = {lm.code: lm for lm in self.landmarks}
        missing = [c for c in codes if c not in lookup or not lookup[c].is_defined]
        if missing:
            raise KeyError(f"{self.surface} landmarks not defined: {', '.join(missing)}")
        return np.stack([lookup[c].position for c in codes]) if codes else np.zeros((0, 3))

    def as_dict(self) -> dict[str, np.ndarray]:
        """``{code: (3,) position}`` for defined points."""
        return {lm.code: lm.position for lm in self.landmarks if lm.is_defined}

    # -------------------------------------------------------------- edits
    def with_landmark(self, landmark: Landmark) -> LandmarkSet:
        """Insert or replace by code (keeps the position in the order)."""
        items = list(self.landmarks)
        for i, lm in enumerate(items):
            if lm.code == landmark.code:
                items[i] = landmark
                return LandmarkSet(self.surface, tuple(items))
        return LandmarkSet(self.surface, (*items, landmark))

    def without(self, code: str) -> LandmarkSet:
        return LandmarkSet(self.surface, tuple(lm for lm in self.landmarks if lm.code != code))

    def transformed(self, matrix: np.ndarray) -> LandmarkSet:
        """Apply a 4x4 homogeneous transform to every defined point."""
        m = np.asarray(matrix, dtype=np.float64)
        out = []
        for lm in self.landmarks:
            if lm.is_defined:
                p = m[:3, :3] @ lm.position + m[:3, 3]
                out.append(Landmark(lm.code, p, lm.status, lm.confidence, lm.description))
            else:
                out.append(lm)
        return LandmarkSet(self.surface, tuple(out))

    def warped(self, warp: Callable[[np.ndarray], np.ndarray]) -> LandmarkSet:
        """Every defined point moved by ``warp`` (``(k, 3) → (k, 3)``, one call)."""
        defined = [lm for lm in self.landmarks if lm.is_defined]
        if not defined:
            return self
        moved = warp(np.array([lm.position for lm in defined]))
        new = {lm.code: lm.moved(p, lm.status) for lm, p in zip(defined, moved, strict=True)}
        return LandmarkSet(self.surface, tuple(new.get(lm.code, lm) for lm in self.landmarks))

    def equals(self, other: LandmarkSet) -> bool:
        return (
            self.surface == other.surface
            and len(self) == len(other)
            and all(a.equals(b) for a, b in zip(self.landmarks, other.landmarks, strict=True))
        )

    @classmethod
    def from_points(
        cls, surface: str, points: Mapping[str, Iterable[float]], status: str = "placed"
    ) -> LandmarkSet:
        """Build from ``{code: (x, y, z)}`` in mm."""
        return cls(
            surface, tuple(Landmark(c, np.asarray(p, float), status) for c, p in points.items())
        )


def merge_user_landmarks(found: LandmarkSet, given: LandmarkSet | None) -> LandmarkSet:
    """Landmarks ``found`` by a method (a registration's suggestions) with what a person
    decided kept: landmarks they placed stay where they are, landmarks they marked absent
    by hand (confidence above 0.5; a method's "absent" has 0) stay absent, and their
    landmarks of codes the method does not give are kept.  The surface is ``found``'s."""
    if given is None:
        return found
    keep = {
        lm.code: lm
        for lm in given
        if lm.status == "placed" or (lm.status == "absent" and lm.confidence > 0.5)
    }
    out = [keep.get(lm.code, lm) for lm in found]
    out += [lm for lm in given if lm.code not in found]
    return LandmarkSet(found.surface, tuple(out))
