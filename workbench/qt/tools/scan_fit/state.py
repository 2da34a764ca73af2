"""The scan-fit tool's plain data: its settings, an opened scan, a fit ready to draw, the
landmarks the user placed and the command that changes them on the window's undo stack
(no Qt here, so the panel and the tool both use them without importing each other).

Units mm; positions in the scan's frame unless a docstring says the head frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from workbench.commands.stack import Command
from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh

if TYPE_CHECKING:
    from workbench.core.colour_transfer import ScanColours, SkinColours
    from workbench.model.case import Case
    from workbench.services.scan_fit.settings import ScanFit

#: ends the Edit menu's label of a scan edit: the step is on the case's stack, the
#: landmarks are not in the case
SCAN_FIT_LABEL = " (scan fit)"


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

    Colours (:func:`workbench.io.scan_colours.read_scan_colours`): ``colours``
    are the file's own (vertex colours, or a texture image with per-corner
    texture coordinates), aligned with ``mesh``; ``working_colours`` the same
    carried onto the working scan the fit uses (the pack's
    :func:`~workbench.io.scan_colours.colours_on_working_scan`), so the fit's
    skin takes them as the pack's does.  Both None when the file carries none,
    or they could not be read: ``colour_note`` then says why (the scan opens
    all the same).  ``vertex_of``: each file vertex's working vertex (-1: left
    out; None when the working scan was simplified), to show the fit's distances
    on the file's mesh.
    """

    path: Path
    units: str
    scale: float | None
    mesh: Mesh
    factor: float
    codes: tuple[str, ...]
    names: dict[str, str]
    messages: tuple[str, ...] = ()
    colours: ScanColours | None = None
    working_colours: ScanColours | None = None
    colour_note: str = ""
    vertex_of: np.ndarray | None = None


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
    skin_colours : SkinColours, optional
        The scan's colours carried onto the fitted skin (one per skin vertex,
        so also per vertex of each of ``skin_parts``, which share its
        vertices): :func:`~workbench.core.colour_transfer.transfer_colours`
        as the pack does, observed where the scan is close, filled elsewhere.
        None when the scan has no colours.
    detail_colours : SkinColours, optional
        The same for the detailed skin's vertices (``detail_parts``).
    colour_note : str
        Why the fitted skin carries no colours although the scan has them.
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
    skin_colours: SkinColours | None = None
    detail_colours: SkinColours | None = None
    colour_note: str = ""


@dataclass
class ScanLandmarks:
    """The landmarks the user placed on the scan (mm, the scan's frame, status "placed").

    They change only through :class:`EditScanLandmarks` commands, pushed on the
    window's one undo stack: :meth:`place`, :meth:`place_many` and :meth:`remove`
    return the command for a change (None when nothing would change) without doing
    it.  ``scan_number`` counts the scans opened (:meth:`clear`), so that undoing a
    step made on an earlier scan leaves the placements on a later one alone;
    ``scan`` is the open scan's file name (for the audit log) and ``on_change``
    is called whenever a command changed :attr:`placed` (the tool redraws).
    """

    placed: LandmarkSet = field(default_factory=lambda: LandmarkSet("skin"))
    scan_number: int = 0
    scan: str = ""
    on_change: Callable[[], None] | None = field(default=None, repr=False, compare=False)

    def change(self, label: str, new: LandmarkSet) -> EditScanLandmarks | None:
        """The command that makes ``new`` the placed set (None if it is the placed set)."""
        if new.equals(self.placed):
            return None
        return EditScanLandmarks(
            self.scan,
            changed_codes(self.placed, new),
            new,
            self.placed,
            self,
            self.scan_number,
            label=label + SCAN_FIT_LABEL,
        )

    def place(self, code: str, position: np.ndarray, label: str = "") -> EditScanLandmarks | None:
        lm = Landmark(code, np.asarray(position, float), "placed")
        what = label or ("Move" if code in self.placed else "Place")
        return self.change(f"{what} {code}", self.placed.with_landmark(lm))

    def place_many(self, points: dict[str, np.ndarray], label: str) -> EditScanLandmarks | None:
        new = self.placed
        for code, p in points.items():
            new = new.with_landmark(Landmark(code, np.asarray(p, float), "placed"))
        return self.change(label, new)

    def remove(self, code: str) -> EditScanLandmarks | None:
        if code not in self.placed:
            return None
        return self.change(f"Remove {code}", self.placed.without(code))

    def clear(self, scan: str = "") -> None:
        """A new scan (its file name): no placements, and the steps made on the previous
        scan no longer act."""
        self.placed = LandmarkSet("skin")
        self.scan_number += 1
        self.scan = scan


def changed_codes(before: LandmarkSet, after: LandmarkSet) -> list[str]:
    """Codes placed, moved or removed between ``before`` and ``after`` (sorted)."""
    out = []
    for code in sorted(set(before.codes) | set(after.codes)):
        a, b = before.get(code), after.get(code)
        if a is None or b is None or not np.array_equal(a.position, b.position):
            out.append(code)
    return out


@dataclass(eq=False)
class EditScanLandmarks(Command):
    """One change of the scan fit's placed landmarks, as a step of the window's undo stack.

    The step sits on the case's :class:`~workbench.commands.stack.CommandStack`
    (Edit ▸ Undo/Redo, the audit log) but does not change the case: the scan and
    its landmarks are not part of it (see :mod:`workbench.qt.tools.scan_fit`).
    ``do`` / ``undo`` put the placed set after / before the change into the
    tool's :class:`ScanLandmarks` and call its ``on_change`` (the tool redraws);
    once another scan was opened they do nothing.  Audited: the scan file's name
    and the codes changed, with the placed set after the change.
    """

    scan: str
    codes: list[str]
    placed: LandmarkSet
    _before: LandmarkSet
    _holder: ScanLandmarks
    _scan_number: int

    def do(self, case: Case) -> None:
        self._put(self.placed)

    def undo(self, case: Case) -> None:
        self._put(self._before)

    def _put(self, placed: LandmarkSet) -> None:
        if self._holder.scan_number != self._scan_number:
            return  # made on a scan that is no longer open
        self._holder.placed = placed
        if self._holder.on_change is not None:
            self._holder.on_change()
