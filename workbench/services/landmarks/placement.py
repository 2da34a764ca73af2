"""Place, slide, snap, mark absent and delete landmarks on a surface, as undoable commands.

The scriptable side of the landmark editor (Kähler §8.6.4: "pick a point on
the skull surface to create a landmark, then slide it on the surface to
fine-tune").  Every position handed in is snapped to the surface (closest
point, via the mesh's spatial index) before it becomes a command on the
case's one undo stack, so a landmark never floats off the bone.
:meth:`SurfacePlacement.snap_to_feature` moves a skull landmark to the
feature its definition names (:mod:`workbench.services.landmarks.snap`).  Codes are
checked against the landmark catalogue (labels such as ``"Nasion"`` or
``"zy l"`` are normalised to their codes).

Units and frame: mm, in the frame of the case's specimen mesh.
"""

from __future__ import annotations

import numpy as np

from workbench.commands.landmarks import (
    DeleteLandmark,
    MoveLandmark,
    PlaceLandmark,
    SetLandmarkStatus,
)
from workbench.commands.stack import CommandStack
from workbench.core.errors import LandmarkError
from workbench.core.landmarks import Landmark
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.io.catalogue import LandmarkCatalogue, load_catalogue
from workbench.io.snap_rules import load_snap_rules
from workbench.services.landmarks.snap import SnapResult, snap_landmark

#: a point handed in farther than this from the surface is refused, not snapped
MAX_SNAP_MM = 20.0


class SurfacePlacement:
    """Landmark editing on one mesh of a case.

    Parameters
    ----------
    mesh : Mesh
        The surface the landmarks live on (mm).
    stack : CommandStack
        The case's undo stack; every change is one command on it.
    surface : "skull" | "skin"
    """

    def __init__(
        self,
        mesh: Mesh,
        stack: CommandStack,
        surface: str = "skull",
        catalogue: LandmarkCatalogue | None = None,
    ):
        self.mesh = mesh
        self.stack = stack
        self.surface = surface
        self.catalogue = catalogue or load_catalogue()
        self._index = MeshIndex(mesh)

    # ------------------------------------------------------------------ queries
    def code(self, label: str) -> str:
        """Catalogue code for a label or code (LandmarkError if unknown)."""
        return self.catalogue.normalise(label, self.surface)

    def snap(self, point: np.ndarray) -> np.ndarray:
        """Closest point of the surface to ``point`` (mm)."""
        p = np.asarray(point, dtype=float).reshape(1, 3)
        cp = self._index.closest_points(p)
        if cp.distances[0] > MAX_SNAP_MM:
            raise LandmarkError(
                f"the point is {cp.distances[0]:.1f} mm from the {self.surface}; "
                f"pick on the surface (within {MAX_SNAP_MM:g} mm)"
            )
        return cp.points[0]

    def landmark(self, code: str) -> Landmark | None:
        lms = self.stack.case.landmarks.get(self.surface)
        return None if lms is None else lms.get(self.code(code))

    def _edited(self, code: str) -> Landmark:
        """The landmark ``code`` just edited (it is in the set now)."""
        lm = self.landmark(code)
        if lm is None:
            raise LandmarkError(f"{code} is not in the {self.surface} landmarks after the edit")
        return lm

    # ------------------------------------------------------------------ edits
    def place(self, code: str, point: np.ndarray) -> Landmark:
        """Place (or re-place) ``code`` at the surface point nearest ``point``."""
        c = self.code(code)
        self.stack.push(PlaceLandmark(surface=self.surface, code=c, position=self.snap(point)))
        return self._edited(c)

    def move(self, code: str, point: np.ndarray) -> Landmark:
        """Move a placed or suggested landmark to the surface point nearest ``point``.

        Consecutive moves of one landmark merge into one undo step (a drag).
        """
        c = self.code(code)
        self.stack.push(MoveLandmark(surface=self.surface, code=c, position=self.snap(point)))
        return self._edited(c)

    def slide(self, code: str, offset_mm: np.ndarray, steps: int = 4) -> Landmark:
        """Slide ``code`` over the surface by ``offset_mm``, staying on it.

        The offset is walked in ``steps`` parts, each projected back onto the
        surface, so the landmark follows curved bone instead of cutting
        across it.
        """
        lm = self.landmark(code)
        if lm is None or not lm.is_defined:
            raise LandmarkError(f"{self.surface} landmark {code!r} is not placed; place it first")
        p = lm.position.copy()
        step = np.asarray(offset_mm, dtype=float) / steps
        for _ in range(steps):
            p = self.snap(p + step)
        return self.move(code, p)

    def snap_to_feature(self, code: str) -> SnapResult:
        """Move skull landmark ``code`` to the feature its definition names, near where it is.

        One undo step labelled e.g. ``"Snap g to most anterior midline point"``
        (a ``MoveLandmark``; the landmark becomes ``placed``); nothing is
        pushed when the snap would move it less than 0.01 mm.  Needs the head
        frame (both porions and an orbitale); positions mm, input frame.  See
        :func:`~workbench.services.landmarks.snap.snap_landmark`.
        """
        if self.surface != "skull":
            raise LandmarkError("snapping to a feature is defined for skull landmarks only")
        result = snap_landmark(
            self.mesh, self.stack.case.landmarks["skull"], self.code(code), catalogue=self.catalogue
        )
        if result.moves:
            self.stack.push(
                MoveLandmark(
                    surface="skull", code=result.code, position=result.position, label=result.label
                )
            )
        return result

    def snap_all_to_features(self, codes: list[str] | None = None) -> list[SnapResult]:
        """Snap several skull landmarks at once, as one undo step (mm, input frame).

        ``codes`` default: every placed or suggested landmark that has a snap
        rule.  All are computed from the landmarks as they are before the
        call (same head frame for all, order does not matter), then applied.
        """
        if self.surface != "skull":
            raise LandmarkError("snapping to a feature is defined for skull landmarks only")
        current = self.stack.case.landmarks["skull"]
        if codes is None:
            rules = load_snap_rules()
            codes = [lm.code for lm in current if lm.is_defined and lm.code in rules]
        results = [
            snap_landmark(self.mesh, current, self.code(c), catalogue=self.catalogue) for c in codes
        ]
        moves = [
            MoveLandmark(surface="skull", code=r.code, position=r.position, label=r.label)
            for r in results
            if r.moves
        ]
        if len(moves) == 1:
            self.stack.push(moves[0])
        elif moves:
            with self.stack.group(f"Snap {len(moves)} skull landmarks to their features"):
                for move in moves:
                    self.stack.push(move)
        return results

    def mark_absent(self, code: str) -> Landmark:
        """The anatomy is missing or damaged: the landmark gets no position and no dowel."""
        c = self.code(code)
        self.stack.push(SetLandmarkStatus(surface=self.surface, code=c, status="absent"))
        return self._edited(c)

    def confirm(self, code: str) -> Landmark:
        """Turn a suggested landmark into a placed one (confidence 1)."""
        c = self.code(code)
        self.stack.push(SetLandmarkStatus(surface=self.surface, code=c, status="placed"))
        return self._edited(c)

    def delete(self, code: str) -> None:
        self.stack.push(DeleteLandmark(surface=self.surface, code=self.code(code)))
