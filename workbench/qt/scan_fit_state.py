"""The scan-fit tool's plain data: its settings, an opened scan, a fit ready to draw and
the landmarks the user placed with their own undo list (no Qt here, so the panel and the
tool both use them without importing each other).

Units mm; positions in the scan's frame unless a docstring says the head frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh

if TYPE_CHECKING:
    from workbench.services.scan_fit.settings import ScanFit


@dataclass(frozen=True)
class ScanFitSettings:
    """Sex, depth table and build of the fit (the panel's choices)."""

    sex: str = "male"
    table: str = DEFAULT_DEPTH_TABLE
    build: str | float = "normal"


@dataclass(frozen=True)
class OpenedScan:
    """A scan read as ``workbench fit-scan`` reads it (mm, the file's frame).

    ``units`` / ``scale`` are what the user chose (given again to the pack
    writer); ``factor`` is the mm per file unit applied; ``codes`` the
    reference head's skin landmark codes with their ``names``.
    """

    path: Path
    units: str
    scale: float | None
    mesh: Mesh
    factor: float
    codes: tuple[str, ...]
    names: dict[str, str]
    messages: tuple[str, ...] = ()


@dataclass(frozen=True)
class FitView:
    """A fit ready to draw: everything in the scan's input frame (mm).

    Attributes
    ----------
    fit : ScanFit
        The service's result (head frame).
    skin : Mesh
        The fitted skin in the scan's frame.
    skin_parts : (Mesh, Mesh)
        Its triangles over no scan (holes, outside the scan: drawn over the scan)
        and those on the scan (drawn only while the scan is hidden: the two
        lie within a fraction of a millimetre, and would show stripes of both).
    distance : (n_scan,) float
        Per scan vertex distance to the fitted skin (mm, NaN = not counted).
    guess : dict
        ``{code: position}`` of the fitted skin landmarks.
    over_holes : frozenset
        Codes the service marks absent (over no scan).
    to_scan_mm : dict
        ``{code: distance}`` of each guess to the scan surface (its confidence).
    anterior, superior : (3,)
        The fitted head's face and up directions in the scan's frame (camera).
    face_bounds : (6,)
        ``xmin, xmax, ymin, ymax, zmin, zmax`` of the fitted face (camera).
    detail_parts : (Mesh, Mesh), optional
        The same two parts of the detailed skin (the fit's detail layer over
        the subdivided skin), when the fit has one.
    seeds : int
        Placed landmarks the fit was given.
    confidence : dict
        ``{code: 0..1}``: the service's confidence in each guess (from its
        distance to the scan; low over holes).
    """

    fit: ScanFit
    skin: Mesh
    skin_parts: tuple[Mesh, Mesh]
    distance: np.ndarray
    guess: dict[str, np.ndarray]
    over_holes: frozenset[str]
    to_scan_mm: dict[str, float]
    anterior: np.ndarray
    superior: np.ndarray
    face_bounds: np.ndarray
    seeds: int = 0
    confidence: dict[str, float] = field(default_factory=dict)
    detail_parts: tuple[Mesh, Mesh] | None = None


@dataclass
class ScanLandmarks:
    """The landmarks the user placed on the scan, with a local undo / redo list.

    Positions mm in the scan's frame, status "placed".  Each change stores the
    previous set (``undo``) and clears the redo list.
    """

    placed: LandmarkSet = field(default_factory=lambda: LandmarkSet("skin"))
    _undo: list[tuple[str, LandmarkSet]] = field(default_factory=list)
    _redo: list[tuple[str, LandmarkSet]] = field(default_factory=list)

    def change(self, label: str, new: LandmarkSet) -> bool:
        if new.equals(self.placed):
            return False
        self._undo.append((label, self.placed))
        self._redo.clear()
        self.placed = new
        return True

    def place(self, code: str, position: np.ndarray, label: str = "") -> bool:
        lm = Landmark(code, np.asarray(position, float), "placed")
        what = label or ("Move" if code in self.placed else "Place")
        return self.change(f"{what} {code}", self.placed.with_landmark(lm))

    def place_many(self, points: dict[str, np.ndarray], label: str) -> bool:
        new = self.placed
        for code, p in points.items():
            new = new.with_landmark(Landmark(code, np.asarray(p, float), "placed"))
        return self.change(label, new)

    def remove(self, code: str) -> bool:
        if code not in self.placed:
            return False
        return self.change(f"Remove {code}", self.placed.without(code))

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    @property
    def undo_text(self) -> str:
        return self._undo[-1][0] if self._undo else ""

    @property
    def redo_text(self) -> str:
        return self._redo[-1][0] if self._redo else ""

    def undo(self) -> bool:
        if not self._undo:
            return False
        label, before = self._undo.pop()
        self._redo.append((label, self.placed))
        self.placed = before
        return True

    def redo(self) -> bool:
        if not self._redo:
            return False
        label, after = self._redo.pop()
        self._undo.append((label, self.placed))
        self.placed = after
        return True

    def clear(self) -> None:
        self.placed = LandmarkSet("skin")
        self._undo.clear()
        self._redo.clear()
