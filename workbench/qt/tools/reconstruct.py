"""The "Reconstruct" tool: dowels planned as the case changes, the face fitted, drawn, compared.

The controller behind the Dowels, "Reconstruct and guides" and Compare docks.
The dowel plan follows the case (re-planned in the worker whenever a part the
plan depends on changes); "Reconstruct" snapshots the case's typed settings
(:func:`workbench.services.reconstruction.case_steps.fit_inputs`) and fits the face in the worker with
the command line's own pipeline (:func:`workbench.services.reconstruction.case_steps.fit_face`).  The
result is a derived result of the window's :class:`~workbench.qt.session.Session`,
not a part of the case, and is drawn through the scene (face, muscles,
guides), in the guide view, and compared with a true skin when one is loaded.

Units mm; the scene is in the specimen's input frame (the skull file's
coordinates).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from PySide6.QtCore import QObject, QTimer, Signal

from workbench.core import value_state
from workbench.core.appearance import DEFAULT_IRIS
from workbench.qt import dialogs
from workbench.qt.panels.reconstruct_panel import BAND_TITLE
from workbench.qt.scene import is_closed
from workbench.render.visuals.face import VIEW_EYE_LEVEL, paint_eyes
from workbench.services.guides.fit_guides import stored_guides
from workbench.services.reconstruction import case_steps, stored_fit
from workbench.services.reconstruction.preview_fit import PreviewFit
from workbench.services.reconstruction.refit_check import (
    RefitChange,
    compare_refit,
    moved_landmarks,
)
from workbench.services.reconstruction.service import (
    MAX_WORKING_TRIANGLES,
    FitInputs,
    reusable_registration,
)

if TYPE_CHECKING:
    from PySide6.QtWidgets import QDockWidget, QWidget

    from workbench.qt.document import Document
    from workbench.qt.guide_view import GuideView
    from workbench.qt.lod import InteractiveDetail
    from workbench.qt.panels.compare_panel import ComparePanel
    from workbench.qt.panels.dowels_panel import DowelsPanel
    from workbench.qt.panels.reconstruct_panel import ReconstructPanel
    from workbench.qt.scene import SceneView
    from workbench.qt.session import Session
    from workbench.qt.workers import TaskRunner
    from workbench.services.reconstruction.stored_fit import StoredFit
    from workbench.services.registration.result import SkullRegistration

#: the frame needs these (porions, orbitales, nasion) before dowels can be planned
FRAME_CODES = ("po_l", "po_r", "or_l", "or_r")
#: the colour bar titles of the face's colourings (spread, band)
FACE_BARS = ("spread mm", BAND_TITLE)
#: ms without a build slider move before the skull is drawn in full again
BUILD_REST_MS = 300
#: case parts the dowels and the fit depend on: a change re-plans (and re-fits)
FIT_PARTS = ("specimen", "landmarks", "dowels", "orientation", "guides")


class ReconstructHost(Protocol):
    """What the tool uses of the window: messages, the guide view's toggle, the docks,
    whether someone is there to answer a question and the dialogs' parent."""

    messages: list[str]
    interactive: bool

    @property
    def docks(self) -> dict[str, QDockWidget]: ...

    def window(self) -> QWidget: ...

    def status(self, text: str) -> None: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...

    def show_guide_view(self, on: bool, draw: bool = True) -> None: ...


class ReconstructTool(QObject):
    """Dowel plan, face fit, its drawing and the comparison (see the module docstring).

    ``held_changed(bool)``: a refit is held back (True) or no longer (False).

    Parameters
    ----------
    document, session, runner
        The case, the derived results, the worker.
    scene, plotter, detail
        The main 3D view's layers, the view itself, the light skull while the build
        slider moves.
    guide_view
        The second view (the fit's guides).
    reconstruct_panel, dowels_panel, compare_panel
        The docks this tool reads and fills.
    host
        The window (status line, errors, the guide view's toggle, the docks).
    """

    held_changed = Signal(bool)

    def __init__(
        self,
        document: Document,
        session: Session,
        runner: TaskRunner,
        scene: SceneView,
        plotter: Any,
        detail: InteractiveDetail,
        guide_view: GuideView,
        reconstruct_panel: ReconstructPanel,
        dowels_panel: DowelsPanel,
        compare_panel: ComparePanel,
        host: ReconstructHost,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        #: a refit held back because it would break the face, with why (see :meth:`show_fit`)
        self.held: tuple[case_steps.FitResult, RefitChange] | None = None
        #: seconds from an edit to its previewed face (:meth:`preview_edit`; tests, benchmarks)
        self.edit_timings: list[float] = []
        self.document, self.session, self.runner = document, session, runner
        self.scene, self.plotter, self.detail = scene, plotter, detail
        self.guide_view = guide_view
        self.reconstruct_panel = reconstruct_panel
        self.dowels_panel = dowels_panel
        self.compare_panel = compare_panel
        self.host = host
        panel = reconstruct_panel
        panel.reconstruct_requested.connect(self.reconstruct)
        panel.accept_held_requested.connect(self.accept_held)
        panel.discard_held_requested.connect(self.discard_held)
        self.held_changed.connect(
            lambda on: panel.show_held(self.held[1].text() if on and self.held else None)
        )
        panel.colouring_changed.connect(lambda _v: self.draw_face())
        panel.build_changed.connect(self.show_build)
        # while the build slider moves the skull is drawn light (lod.py); full quality again
        # once it rests (released, or no move for BUILD_REST_MS)
        self._build_rest = QTimer(self)
        self._build_rest.setSingleShot(True)
        self._build_rest.setInterval(BUILD_REST_MS)
        self._build_rest.timeout.connect(self._build_rested)
        panel.build_slider.sliderReleased.connect(self._build_rest.start)
        session.fit_changed.connect(panel.show_result)
        runner.cancelled.connect(self._cancelled)
        session.truth_changed.connect(lambda truth: compare_panel.show_comparison(truth[0], None))

    # ------------------------------------------------------------ dowels
    def schedule_dowels(self) -> None:
        case = self.document.case
        lms = case.landmarks["skull"]
        if case.specimen.mesh is None or not all(c in lms.as_dict() for c in FRAME_CODES):
            self.session.set_preview(None)
            self.scene.clear("dowels")
            self.dowels_panel.show_plan(
                None, "Dowels appear once the porions and orbitales are placed (or suggested)."
            )
            return
        skull, settings = case.specimen.mesh, case_steps.depth_settings(case)
        self.runner.submit(
            "dowels",
            "Planning dowels …",
            lambda: case_steps.preview_dowels(skull, lms, settings),
            self._show_dowels,
            self._dowels_failed,
        )

    def _show_dowels(self, preview: case_steps.DowelPreview) -> None:
        self.session.set_preview(preview)
        self.scene.show_dowels(preview.origins, preview.tips)
        self.dowels_panel.show_plan(preview)

    def _dowels_failed(self, exc: BaseException) -> None:
        self.session.set_preview(None)
        self.scene.clear("dowels")
        self.dowels_panel.show_plan(None, dialogs.error_text("No dowels", exc)[0])

    # ------------------------------------------------------------ reconstruct
    def reconstruct(self, after_edit: bool = False) -> None:
        """Fit the face in the worker (guides and ensemble as the panel says), with
        progress and Cancel.

        A refit reuses the registration of the shown fit (or of Suggest) when the
        skull, its orientation and the reference head are the same
        (:func:`~workbench.services.reconstruction.service.reusable_registration`).
        ``after_edit``: a case edit asked for it; the face is previewed at once
        (:meth:`preview_edit`) while the refit runs.
        """
        case = self.document.case
        if case.specimen.mesh is None:
            self.host.status("Open a skull first.")
            return
        panel = self.reconstruct_panel
        try:  # the snapshot the worker fits; the user may go on editing the case
            inputs = case_steps.fit_inputs(
                case, use_guides=panel.use_guides.isChecked(), ensemble=panel.ensemble.value()
            )
        except Exception as exc:  # noqa: BLE001 - shown as a readable message
            self.host.show_error("The stored guides are not usable", exc)
            return
        registration = self._reusable_registration(inputs)
        if after_edit:
            self.preview_edit()
        self.runner.submit(
            "fit",
            "Refitting the face …" if registration is not None else "Reconstructing the face …",
            lambda report: case_steps.fit_face(inputs, report, registration),
            self.show_fit,
            lambda exc: self.host.show_error("Could not reconstruct the face", exc),
            progress=True,
        )

    def _cancelled(self, channel: str) -> None:
        """A fit was cancelled: the face of the last fit again (not an edit's preview)."""
        if channel == "fit" and not self.scene.closed:
            self.draw_face()
            if self.session.fit is not None:
                self.host.messages.append(
                    "Fit cancelled: the face shown is the last fit; the edits after it are kept "
                    "in the case (Reconstruct fits them)."
                )

    def _reusable_registration(self, inputs: FitInputs) -> SkullRegistration | None:
        """The registration a fit of ``inputs`` may reuse: the shown fit's, or Suggest's of
        the same skull, orientation and sex (None: the fit registers the skull itself)."""
        reg = reusable_registration(self.session.fit, inputs)
        made = self.session.suggested_registration
        if reg is None and made is not None and inputs.skull.n_faces <= MAX_WORKING_TRIANGLES:
            skull, orient, sex, suggested = made
            same = skull is inputs.skull and orient == inputs.hint and sex == inputs.dowels.sex
            if same and inputs.template is None:
                reg = suggested
        return reg

    def preview_edit(self) -> bool:
        """Show the face as the edit just made moves it, at once (the refit follows).

        The last fit's warp is re-solved with the dowel tips of the moved skull
        landmarks and the targets of the changed guides
        (:class:`~workbench.services.reconstruction.preview_fit.PreviewFit`, a few ms);
        False when the edit is not of that kind (a landmark added or removed,
        dowel settings): the face then changes when the refit arrives.
        """
        fit = self.session.fit
        if fit is None or fit.recon.landmarks is None or not self.scene.has("face"):
            return False
        t0 = time.perf_counter()
        try:
            preview = PreviewFit.from_fit(fit.recon, fit.head)
        except ValueError:
            return False
        case = self.document.case
        # against the case's landmarks when it was fitted (the fit's own may be articulated
        # or snapped): only those the user changed since are moved
        given = fit.inputs.landmarks if fit.inputs and fit.inputs.landmarks else fit.recon.landmarks
        moved = False
        for code, places in moved_landmarks(given, case.landmarks["skull"].defined()).items():
            if len(places) == 2:  # moved (not added or removed: the refit decides those)
                moved = preview.move_landmark(code, places[1]) or moved
        if case.guides is not None:
            shown = {g.id: g for g in fit.guides}
            for guide in stored_guides(case.guides) or ():
                old = shown.get(guide.id)
                if old is None or old.value != guide.value or old.enabled != guide.enabled:
                    moved = preview.move_guide(guide) or moved
        if not moved:
            return False
        self.scene.update_points("face", preview.skin())
        self.edit_timings.append(time.perf_counter() - t0)
        self.host.status("Face previewed from the edit; the refit follows …")
        return True

    def show_fit(self, fit: case_steps.FitResult) -> None:
        """Show a new fit, unless it would break the face shown (:func:`compare_refit`):
        then the previous face stays, the new one is held (:attr:`held`) and the user is
        asked (:meth:`accept_held`, :meth:`discard_held`)."""
        previous = self.session.fit
        if previous is not None:
            change = compare_refit(previous, fit)
            if not change.safe:
                self._hold(fit, change)
                return
        self._apply_fit(fit)

    def _hold(self, fit: case_steps.FitResult, change: RefitChange) -> None:
        """Keep the face on screen; the new fit waits for the user's word."""
        self.held = (fit, change)
        self.held_changed.emit(True)
        self.scene.show_held(fit.recon.face)  # the new face as a ghost over the one kept
        text = (
            f"The new face was not applied: {change.text()}. The previous face is still "
            "shown; accept the new one (Reconstruct dock) or undo the edit (Ctrl+Z)."
        )
        self.host.status(text)
        self.host.messages.append(text)
        if not self.host.interactive:
            return
        from PySide6.QtWidgets import QMessageBox

        answer = QMessageBox.question(
            self.host.window(),
            "Apply the new face?",
            f"The refit after your edit would change the face where you did not edit it:\n\n"
            f"{change.text()}.\n\nApply it anyway? (No keeps the previous face; undo the edit "
            "with Ctrl+Z to go back.)",
            QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No,
            QMessageBox.StandardButton.No,
        )
        if answer == QMessageBox.StandardButton.Yes:
            self.accept_held()

    def accept_held(self) -> None:
        """Apply the refit that was held back."""
        if self.held is None:
            return
        fit, _change = self.held
        self._apply_fit(fit)

    def discard_held(self) -> None:
        """Drop the refit that was held back (the previous face stays)."""
        if self.held is not None:
            self._release_held()
            self.host.status("The new face was discarded; the previous face stays.")

    def _release_held(self) -> None:
        """No refit is held back any more: the note, the buttons and the ghost go."""
        self.held = None
        self.held_changed.emit(False)
        self.scene.show_held(None)

    def restore(self, stored: StoredFit) -> None:
        """Show the face a reopened case keeps, as it was saved (no fitting).

        The panel takes the fit's guide and ensemble choices.  A *stale* face
        (the case's inputs are not those it was fitted from) is shown with a
        warning and, when "Re-fit on change" is on, fitted again in the worker.
        """
        fit, panel = stored.fit, self.reconstruct_panel
        if fit.inputs is not None:
            blocked = [w.blockSignals(True) for w in (panel.use_guides, panel.ensemble)]
            panel.use_guides.setChecked(fit.inputs.use_guides)
            panel.ensemble.setValue(fit.inputs.ensemble)
            for w, b in zip((panel.use_guides, panel.ensemble), blocked, strict=True):
                w.blockSignals(b)
        self._apply_fit(fit, restored=True)
        when = f" (fitted by version {stored.software})" if stored.software else ""
        if stored.current:
            text = f"The face kept in the case is shown as it was saved{when}."
        else:
            text = (
                f"STALE: the face kept in the case was fitted from other inputs than the case "
                f"has now{when}; reconstruct (Ctrl+R) before using it."
            )
        self.host.messages.append(text)
        self.host.status(text)
        if not stored.current and panel.auto_refit.isChecked():
            self.reconstruct()

    def _apply_fit(self, fit: case_steps.FitResult, restored: bool = False) -> None:
        if self.held is not None:  # applied, or a newer fit replaces the one held back
            self._release_held()
        self.session.set_fit(fit)  # the reconstruct panel follows (fit_changed)
        self._keep_in_case(fit)
        reg = fit.recon.registration
        check = {} if reg is None else reg.figures.get("self_check") or {}
        if check.get("outcome") == "check":
            # the self-check's doubt first (issue 28): the user confirms before using the face
            self.host.status(f"CHECK: {check['reasons'][0]} (face fitted; confirm the orientation)")
        elif not restored:
            self.host.status(f"Face fitted in {self.runner.timings.get('fit', 0):.1f} s")
        if not self.guide_view.isVisible() and not self.guide_view.closed_by_user:
            # the first fit opens the guide view.  Both views then repaint
            # in one pass (the main view narrows, the new one appears), so
            # open it while both are cheap to draw (the new one empty, the
            # main one without the face) and draw the fit after that paint
            self.host.show_guide_view(True, draw=False)
            self.scene.after_paint(lambda f=fit: self._draw_fit(f), render=False)
        else:
            self._draw_fit(fit)

    def _keep_in_case(self, fit: case_steps.FitResult) -> None:
        """The face shown is the one the case keeps (a derived result, saved with the case)."""
        try:
            self.document.case.derived[stored_fit.KEY] = stored_fit.fit_to_state(fit)
        except (stored_fit.StoredFitError, value_state.StateError) as exc:
            self.document.case.derived.pop(stored_fit.KEY, None)
            self.host.messages.append(f"The face will not be kept in the case file: {exc}")

    def _draw_fit(self, fit: case_steps.FitResult) -> None:
        if fit is not self.session.fit or self.scene.closed:
            return  # a newer fit (or none) is on its way, or the window closed
        self._show_dowels(fit.preview)
        self.draw_face()
        self.draw_muscles()
        self.draw_guides()
        if self.session.truth is not None:
            self.compare()
        # the guide view after the main view's paint: its drawing and paint
        # would otherwise join that paint in one long block of the event loop
        self.scene.after_paint(lambda f=fit: self._show_fit_in_guide_view(f))

    def _show_fit_in_guide_view(self, fit: case_steps.FitResult) -> None:
        if fit is not self.session.fit or is_closed(self.guide_view.plotter):
            return
        self.guide_view.fit_changed()

    def draw_face(self) -> None:
        """The fitted face at the build slider's build, coloured as the panel says.

        "spread" and "band" fall back to the plain skin when the fit has no ensemble
        or no build faces.
        """
        fit = self.session.fit
        if fit is None:
            self.scene.clear("face")
            return
        panel = self.reconstruct_panel
        colouring, z = panel.colouring.currentText(), panel.build_z()
        face = fit.recon.face
        if fit.builds is not None and z is not None and z != fit.builds.main_z:
            face = face.with_vertices(fit.recon.to_input(fit.builds.vertices_at(z)))
        scalars, title = None, ""
        if colouring == "spread" and fit.spread is not None:
            scalars, title = fit.spread, "spread mm"
        elif colouring == "band" and fit.builds is not None:
            scalars, title = fit.builds.half_width_mm, BAND_TITLE
        # pyvista leaves a colour bar placed by position behind when its surface goes
        # (it only frees bars it placed itself): drop the face's other bars by hand
        bars = self.plotter.scalar_bars
        for old in FACE_BARS:
            if old != title and old in bars:
                bars.remove_scalar_bar(old, render=False)
        # the fitted head's eyes, painted (iris, pupil) in the input frame; they stay
        # where they are when the build slider moves the skin
        recon = fit.recon
        chosen = self.document.case.appearance  # the case's iris colour (an artistic choice)
        eyes = paint_eyes(
            recon.mesh_to_input(recon.head.meshes["eyes"]),
            recon.to_input(np.asarray(recon.head.eye_centres, float)),
            level=VIEW_EYE_LEVEL,
            iris=chosen.iris if chosen is not None else DEFAULT_IRIS,
        )
        if scalars is None:
            self.scene.show_face(face, eyes=eyes)
        else:
            self.scene.show_face(face, scalars, title, eyes=eyes)

    def show_build(self, z: float) -> None:
        """The build slider moved: morph the drawn face to build score ``z`` in place.

        Only the face's points (and normals) change; its actor, colours and colour bar
        stay, nothing is refitted and nothing goes on the undo stack (view state, see
        :mod:`workbench.qt.panels.reconstruct_panel`).  One render is requested.
        """
        fit = self.session.fit
        if fit is None or fit.builds is None or not self.scene.has("face"):
            return
        self.detail.begin()  # the light skull while the slider moves (_build_rested ends it)
        self._build_rest.start()
        self.scene.update_points("face", fit.recon.to_input(fit.builds.vertices_at(z)))

    def _build_rested(self) -> None:
        """The build slider rests: the skull in full again (one full-quality render)."""
        if self.scene.closed or self.reconstruct_panel.build_slider.isSliderDown():
            return  # (held: its release restarts the timer)
        self.detail.end()

    def draw_muscles(self) -> None:
        """The fitted head's muscle grids (mm, input frame), 4 mm under the fitted skin.

        Each grid rides on the skin (triangle + barycentric weights + depth,
        see :class:`workbench.model.muscles.MuscleGrid`), so its rows are
        evaluated on the fitted head's skin and mapped to the input frame.
        """
        fit = self.session.fit
        head = fit.recon.head if fit is not None else None
        if fit is None or head is None or not head.muscles:
            self.scene.clear("muscles")
            return
        to_input = fit.recon.to_input
        self.scene.show_muscles(
            [[to_input(row) for row in grid.rows(head.skin)] for grid in head.muscles]
        )

    def draw_guides(self) -> None:
        fit = self.session.fit
        if fit is None:
            self.scene.clear("guides")
            return
        segments, points = case_steps.guide_geometry(fit)
        self.scene.show_guides(segments, points)

    # ------------------------------------------------------------ compare
    def load_truth(self, path: str | Path, scale: float | None = None) -> None:
        from workbench.io.meshes import read_mesh

        path = Path(path)
        self.runner.submit(
            "truth",
            f"Reading {path.name} …",
            lambda: read_mesh(path, units="mm" if scale is None else "auto", scale=scale).mesh,
            lambda mesh: self._truth_loaded(path.name, mesh),
            lambda exc: self.host.show_error(f"Could not read {path.name}", exc),
        )

    def _truth_loaded(self, name: str, mesh: Any) -> None:
        self.session.set_truth(name, mesh)  # the compare panel follows (truth_changed)
        self.scene.show_truth(mesh)
        self.host.docks["compare"].raise_()
        if self.session.fit is not None:
            self.compare()

    def compare(self) -> None:
        from workbench.services.templates.regions import face_regions
        from workbench.services.validation.compare import compare_surfaces

        fit, truth_loaded = self.session.fit, self.session.truth
        if truth_loaded is None or fit is None:
            return
        name, truth = truth_loaded
        face, regions = fit.recon.face, face_regions(fit.head)
        self.runner.submit(
            "compare",
            "Comparing with the true skin …",
            lambda: compare_surfaces(face, truth, recon_regions=regions),
            self._show_comparison,
            lambda exc: self.host.show_error("Could not compare", exc),
        )

    def _show_comparison(self, comparison: Any) -> None:
        truth_loaded = self.session.truth
        if truth_loaded is None:  # a comparison is only started with a true skin
            raise RuntimeError("a comparison arrived without a true skin")
        self.session.set_comparison(comparison)
        name, truth = truth_loaded
        self.scene.show_truth(truth, comparison.truth_vertex_values())
        self.compare_panel.show_comparison(name, comparison)
        self.host.status(
            f"Compared with {name}: mean |distance| "
            f"{comparison.figures['mean_abs_mm']:.2f} mm "
            f"({self.runner.timings.get('compare', 0):.1f} s)"
        )
