"""Skull landmark operations of the main window: draw, place by click, suggest, snap.

A tool the main window composes (:class:`LandmarkTool`, built from the
document, the scene, the landmarks panel and the worker); every change is
an undoable command pushed on the document.  Suggesting runs in
the worker; snapping is computed on the GUI thread (a few ms: the search
structures are built in the worker when the skull opens).  Positions are mm
in the skull file's (input) frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from workbench.commands.landmarks import MoveLandmark, PlaceLandmark, ReplaceLandmarkSet
from workbench.core.errors import WorkbenchError
from workbench.services.landmarks.snap import SnapResult, snap_landmark
from workbench.services.reconstruction import case_steps

if TYPE_CHECKING:
    from workbench.io.catalogue import LandmarkCatalogue
    from workbench.qt.document import Document
    from workbench.qt.hosts import Feedback
    from workbench.qt.panels.landmarks_panel import LandmarksPanel
    from workbench.qt.scene import SceneView
    from workbench.qt.session import Session
    from workbench.qt.workers import TaskRunner


#: a snap moving a landmark farther than this (mm) is applied only when the user confirms
MAX_SNAP_MM = 10.0


class LandmarkTool:
    """Landmark drawing and editing (see the module docstring).

    ``feedback`` (the main window) takes the status line, the error
    messages and the notes of a suggestion.
    """

    def __init__(
        self,
        document: Document,
        scene: SceneView,
        catalogue: LandmarkCatalogue,
        landmarks_panel: LandmarksPanel,
        runner: TaskRunner,
        feedback: Feedback,
        session: Session | None = None,
    ) -> None:
        self.document = document
        self.session = session
        self.scene = scene
        self.catalogue = catalogue
        self.landmarks_panel = landmarks_panel
        self.runner = runner
        self.feedback = feedback

    def status(self, text: str) -> None:
        self.feedback.status(text)

    def show_error(self, what: str, exc: BaseException) -> None:
        self.feedback.show_error(what, exc)

    def draw_landmarks(self, override: dict[str, np.ndarray] | None = None) -> None:
        """Landmarks of the case; ``override`` ({code: position}) draws a drag in progress."""
        lms = self.document.case.landmarks["skull"].defined()
        code = self.landmarks_panel.selected_code()
        override = override or {}
        positions = np.array([override.get(lm.code, lm.position) for lm in lms], float)
        selected, label = None, ""
        if code and code in lms:
            selected = np.asarray(override.get(code, lms[code].position), float)
            entry = self.catalogue.entry(code, "skull")
            # no label while dragging: VTK re-places labels every frame (slow)
            label = "" if override else f"{code}: {entry.name}"
        self.scene.show_landmarks(
            positions.reshape(-1, 3), [lm.status for lm in lms], selected, label
        )

    # ------------------------------------------------------------ landmarks
    def on_pick(self, point: np.ndarray) -> None:
        """A click on the skull: place the selected landmark there."""
        code = self.landmarks_panel.selected_code()
        if not code or not self.landmarks_panel.place_on_click.isChecked():
            self.status("Select a landmark in the list first, then click on the skull.")
            return
        self.document.push(PlaceLandmark(surface="skull", code=code, position=point))

    def suggest_landmarks(self) -> None:
        """Run the automatic transfer in the worker; apply it as one undoable step."""
        case = self.document.case
        if case.specimen.mesh is None:
            self.status("Open a skull first.")
            return
        skull, current = case.specimen.mesh, case.landmarks["skull"]
        sex, orient = case.dowels.sex, case_steps.orientation(case)
        self.runner.submit(
            "suggest",
            "Suggesting skull landmarks …",
            lambda report: case_steps.suggest_landmarks(skull, current, sex, orient, report),
            lambda result: self._apply_suggestion(result, (skull, orient, sex)),
            lambda exc: self.show_error("Could not suggest landmarks", exc),
            progress=True,
        )

    def _apply_suggestion(self, result: tuple, made_for: tuple = ()) -> None:
        new_set, reg = result
        if made_for and self.session is not None:  # the next Reconstruct reuses it
            self.session.suggested_registration = (*made_for, reg)
        if self.document.push(ReplaceLandmarkSet("skull", new_set, "Suggest skull landmarks")):
            n = sum(lm.status == "suggested" for lm in new_set)
            d = reg.figures.get("median_observed_distance_mm")
            self.status(
                f"Suggested {n} landmarks by the dense registration (median bone "
                f"distance {d:.2f} mm, {self.runner.timings.get('suggest', 0):.1f} s)"
            )
            self.feedback.messages.extend(reg.warnings)

    def _snap_is_wanted(self, result: SnapResult) -> bool:
        """A snap that moves the landmark far (more than :data:`MAX_SNAP_MM`) found another
        feature more often than the one meant: it is applied only when the user says so
        (never when nobody is there to ask)."""
        distance = result.moved_mm
        if distance <= MAX_SNAP_MM:
            return True
        question = (
            f"Snapping {result.code} would move it {distance:.1f} mm ({result.explanation}). "
            f"A snap that far has often found another feature than the one meant."
        )
        if self.feedback.interactive:
            from PySide6.QtWidgets import QMessageBox

            answer = QMessageBox.question(
                self.feedback.window(),
                "Move the landmark that far?",
                f"{question}\n\nMove it anyway?",
                QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.Cancel,
                QMessageBox.StandardButton.Cancel,
            )
            if answer == QMessageBox.StandardButton.Yes:
                return True
        self.status(f"Not snapped: {question} Place it by hand where the feature is.")
        self.feedback.messages.append(question)
        return False

    def snap_selected(self) -> None:
        """Snap the selected skull landmark to the feature its definition names ("Snap", S).

        Computed on the GUI thread (a few ms; the search structures are built
        in the worker when the skull opens) and pushed as one undoable move.
        """
        code = self.landmarks_panel.selected_code()
        case = self.document.case
        if not code:
            self.status("Select a landmark in the list first, then Snap (S).")
            return
        if case.specimen.mesh is None:
            self.status("Open a skull first.")
            return
        try:
            result = snap_landmark(
                case.specimen.mesh, case.landmarks["skull"], code, catalogue=self.catalogue
            )
        except (WorkbenchError, ValueError) as exc:
            self.show_error(f"Could not snap {code}", exc)
            return
        if result.moves and not self._snap_is_wanted(result):
            return
        if result.moves and not self.document.push(
            MoveLandmark(
                surface="skull", code=result.code, position=result.position, label=result.label
            )
        ):
            return
        self.status(result.explanation)
