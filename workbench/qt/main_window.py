"""The workbench main window: a 3D view, tool docks, menus, status bar.

Wiring (created in this order in ``__init__``)::

    MainWindow
    ├── Document            case + CommandStack + file; Qt signals for changes
    ├── Session             derived results (fit, dowel preview, true skin, comparison)
    ├── TaskRunner          worker threads; results come back on the GUI thread
    ├── QtInteractor        central 3D view (pyvistaqt)
    │   ├── SceneView       named layers: skull, landmarks, dowels, guides, muscles, face, truth
    │   └── ClickPicker     click (not drag) on the skull → PlaceLandmark
    ├── panels              LandmarksPanel, DowelsPanel, ReconstructPanel, ComparePanel,
    │                       ScanFitPanel, AnimatePanel, AgePanel (docks);
    │                       LayersPanel below them (visibility + opacity per layer)
    ├── tools               FileTool (open, save, export), LandmarkTool (draw, place,
    │                       suggest, snap), DragTool (live drags), ScanFitTool (a face
    │                       scan fitted by the scan-fit service, its landmarks; own picker),
    │                       AnimateTool (the animation service's Animator, live skin),
    │                       AgeTool (the age service under a target-age slider)
    ├── GuideView           second view: guides over the session's fit (drags → DragTool)
    └── menus               actions.ACTIONS (File, Edit, Tools, View + layer toggles)

The window holds no geometry logic: edits are commands pushed on the
document's stack, computations are :mod:`workbench.qt.jobs` functions run in
the worker, and their results are drawn (derived results such as the fitted
face are not part of the case; the typed settings that produce them are:
the ``dowels``, ``orientation`` and ``guides`` parts, and the fit is the
command line's own pipeline, :func:`workbench.qt.jobs.fit_face`).
Units mm; the scene is in the specimen's input frame (the skull file's
coordinates).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import QPoint, QRect, Qt, QTimer
from PySide6.QtGui import QKeySequence, QShortcut
from PySide6.QtWidgets import (
    QApplication,
    QDockWidget,
    QLabel,
    QMainWindow,
    QProgressBar,
    QScrollArea,
    QSplitter,
    QWidget,
)

from workbench.io.catalogue import load_catalogue
from workbench.qt import dialogs, gc_guard, jobs
from workbench.qt.actions import (
    AGE_ACTIONS,
    ANIMATE_ACTIONS,
    SCAN_FIT_ACTIONS,
    add_tool_actions,
    build_menus,
)
from workbench.qt.age_ops import AgeTool
from workbench.qt.animate_ops import AnimateTool
from workbench.qt.document import Document
from workbench.qt.drag_ops import DragTool
from workbench.qt.file_ops import FileTool
from workbench.qt.guide_view import GuideView
from workbench.qt.landmark_ops import LandmarkTool
from workbench.qt.lod import InteractiveDetail
from workbench.qt.panels.age_panel import AgePanel
from workbench.qt.panels.animate_panel import AnimatePanel
from workbench.qt.panels.compare_panel import ComparePanel
from workbench.qt.panels.dowels_panel import DowelsPanel
from workbench.qt.panels.landmarks_panel import LandmarksPanel
from workbench.qt.panels.layers_panel import LayersPanel
from workbench.qt.panels.reconstruct_panel import BAND_TITLE, ReconstructPanel
from workbench.qt.panels.scan_fit_panel import ScanFitPanel
from workbench.qt.picking import ClickPicker
from workbench.qt.scan_fit_ops import ScanFitTool
from workbench.qt.scene import SceneView, is_closed
from workbench.qt.session import Session
from workbench.qt.workers import TaskRunner, preload, show_fraction

if TYPE_CHECKING:
    from workbench.services.case.case_setup import OpenedCase

#: the frame needs these (porions, orbitales, nasion) before dowels can be planned
FRAME_CODES = ("po_l", "po_r", "or_l", "or_r")
#: the colour bar titles of the face's colourings (spread, band)
FACE_BARS = ("spread mm", BAND_TITLE)
#: ms without a build slider move before the skull is drawn in full again
BUILD_REST_MS = 300
#: case parts the dowels and the fit depend on: a change re-plans (and re-fits)
FIT_PARTS = ("specimen", "landmarks", "dowels", "orientation", "guides")


class MainWindow(QMainWindow):
    """See the module docstring.

    Parameters
    ----------
    auto_update : bool or float
        The QtInteractor's periodic render (False in tests).
    interactive : bool
        False: never open modal dialogs (tests, ``--screenshot``); messages
        go to :attr:`messages` and errors to :attr:`errors`.
    """

    def __init__(self, *, auto_update: bool | float = True, interactive: bool = True) -> None:
        super().__init__()
        from pyvistaqt import QtInteractor

        gc_guard.install()  # cyclic garbage (Qt wrappers) collected on this thread only

        self.interactive = interactive
        self.messages: list[str] = []
        self.errors: list[str] = []
        self.catalogue = load_catalogue()
        self.document = Document(on_error=self.show_error, parent=self)
        self.session = Session(self)
        self.runner = TaskRunner(self)
        self.files = FileTool(self.document, self.session, self.runner, self)
        preload()  # what the workers will import, before the event loop runs

        self.plotter = QtInteractor(self, auto_update=auto_update)
        # pyvista's "q" would close the 3D view
        self.plotter.clear_events_for_key("q")  # type: ignore[arg-type]  # pyvista stub bug: wraps-typed method
        # FXAA instead of 4x multisampling: similar edges at a third of the cost
        # (llvmpipe: 180 → 70 ms a frame, 100k triangles); a software renderer
        # then goes without either (SceneView.tune)
        render_window = self.plotter.render_window
        if render_window is None:  # (a new view always has one)
            raise RuntimeError("the 3D view has no render window")
        render_window.SetMultiSamples(0)
        self.plotter.enable_anti_aliasing("fxaa")
        # the 3D view and the optional second view (guides, orthographic) side by side
        self.views = QSplitter(Qt.Orientation.Horizontal, self)
        self.views.addWidget(self.plotter)
        self.setCentralWidget(self.views)
        self.scene = SceneView(self.plotter)
        self.detail = InteractiveDetail(self.plotter, self.runner.submit)
        self._skull_poly: Any = None

        self.landmarks_panel = LandmarksPanel(self.document, self.catalogue)
        self.dowels_panel = DowelsPanel(self.document)
        self.reconstruct_panel = ReconstructPanel(self.document)
        self.compare_panel = ComparePanel()
        self.landmarks = LandmarkTool(
            self.document, self.scene, self.catalogue, self.landmarks_panel, self.runner, self
        )
        self.drags = DragTool(
            self.document,
            self.scene,
            self.session,
            self.detail,
            self.plotter,
            self.landmarks_panel,
            self.reconstruct_panel,
            self.landmarks.draw_landmarks,
            self.draw_face,
        )
        QShortcut(QKeySequence(Qt.Key.Key_Escape), self).activated.connect(self.cancel_drag)
        drags = self.drags
        self.picker = ClickPicker(
            self.plotter,
            self._skull_actor,
            self.landmarks.on_pick,
            target_surface=self._skull_surface,
            grab_target=drags.grab_target,
            on_drag=drags.on_drag,
            on_drag_start=drags.on_drag_start,
            on_drag_end=drags.on_drag_end,
        )
        self.scan_fit_panel = ScanFitPanel()
        self.scan_fit = ScanFitTool(
            self.scan_fit_panel,
            self.scene,
            self.plotter,
            self.runner,
            self,
            skull_picker=self.picker,
            parent=self,
        )
        from workbench.services.animation.animator import EXPRESSIONS

        self.animate_panel = AnimatePanel(EXPRESSIONS)
        self.animate = AnimateTool(
            self.animate_panel, self.scene, self.plotter, self.runner, self, parent=self
        )
        self.age_panel = AgePanel()
        self.age = AgeTool(
            self.age_panel,
            self.scene,
            self.plotter,
            self.runner,
            self,
            fitted_head=lambda: None if self.session.fit is None else self.session.fit.recon.head,
            case_sex=lambda: self.document.case.dowels.sex,
            parent=self,
        )
        self.docks: dict[str, QDockWidget] = {}
        for key, title, panel in (
            ("landmarks", "Skull landmarks", self.landmarks_panel),
            ("dowels", "Dowels", self.dowels_panel),
            ("reconstruct", "Reconstruct and guides", self.reconstruct_panel),
            ("compare", "Compare", self.compare_panel),
            ("fit_scan", "Fit scan", self.scan_fit_panel),
            ("animate", "Animate", self.animate_panel),
            ("age", "Age progression", self.age_panel),
        ):
            dock = QDockWidget(title, self)
            dock.setObjectName(f"dock_{key}")
            dock.setWidget(_scrolling(panel))
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock)
            if self.docks:
                self.tabifyDockWidget(next(iter(self.docks.values())), dock)
            self.docks[key] = dock
        self.docks["landmarks"].raise_()
        self.layers_panel = LayersPanel(self.scene)
        self.docks["layers"] = dock = QDockWidget("Layers", self)
        dock.setObjectName("dock_layers")
        dock.setWidget(_scrolling(self.layers_panel))
        # below the tool tabs: layers stay in reach whichever tool is open
        self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock, Qt.Orientation.Vertical)
        self.resizeDocks([self.docks["landmarks"], dock], [620, 230], Qt.Orientation.Vertical)
        self.resizeDocks([self.docks["landmarks"]], [420], Qt.Orientation.Horizontal)
        self.guide_view = GuideView(
            self.session, self.runner, self.scene, self.reconstruct_panel, self.drags
        )
        self.drags.attach(self.picker, self.guide_view)
        self.scene.also_tune(self.guide_view.plotter)
        self.views.addWidget(self.guide_view)
        self.views.setStretchFactor(0, 3)
        self.views.setStretchFactor(1, 2)
        self.guide_view.hide()  # shown with the first fit, or from the View menu
        self.actions_by_id = build_menus(self)
        self.actions_by_id.update(add_tool_actions(self, self.scan_fit, SCAN_FIT_ACTIONS))
        self.actions_by_id.update(add_tool_actions(self, self, ANIMATE_ACTIONS))
        self.actions_by_id.update(add_tool_actions(self, self, AGE_ACTIONS))

        self.status_label = QLabel("Open a skull mesh, a CT or a case (File menu).")
        self.progress = QProgressBar()
        self.progress.setRange(0, 0)
        self.progress.setMaximumWidth(180)
        self.progress.hide()
        self.statusBar().addWidget(self.status_label, 1)
        self._busy_text, self._status_before = "", ""
        self.statusBar().addPermanentWidget(self.progress)

        self.document.case_replaced.connect(self._on_case_replaced)
        self.document.part_changed.connect(self._on_part)
        self.document.part_changed.connect(
            lambda part: self.guide_view.refresh() if part == "guides" else None
        )
        self.document.stack_changed.connect(self._update_title)
        self.scan_fit.history_changed.connect(self._update_title)
        self.docks["fit_scan"].visibilityChanged.connect(lambda _v: self._update_title())
        self.docks["animate"].visibilityChanged.connect(
            lambda v: self.animate.ensure_loaded() if v else None
        )
        self.docks["age"].visibilityChanged.connect(self.age.set_active)
        self.session.fit_changed.connect(lambda fit: self.age.fit_changed(fit is not None))
        self.runner.busy_changed.connect(self._on_busy)
        self.runner.progress_changed.connect(
            lambda _channel, step, f: show_fraction(self.progress, f, step)
        )
        self.landmarks_panel.selection_changed.connect(lambda _c: self.landmarks.draw_landmarks())
        self.landmarks_panel.suggest_requested.connect(self.landmarks.suggest_landmarks)
        self.landmarks_panel.snap_requested.connect(lambda _code: self.landmarks.snap_selected())
        self.reconstruct_panel.reconstruct_requested.connect(self.reconstruct)
        self.reconstruct_panel.opacity_changed.connect(lambda v: self.scene.set_opacity("face", v))
        self.scene.layer_changed.connect(self._on_layer_changed)
        self.reconstruct_panel.colouring_changed.connect(lambda _v: self.draw_face())
        self.reconstruct_panel.build_changed.connect(self.show_build)
        # while the build slider moves the skull is drawn light (lod.py); full quality again
        # once it rests (released, or no move for BUILD_REST_MS)
        self._build_rest = QTimer(self)
        self._build_rest.setSingleShot(True)
        self._build_rest.setInterval(BUILD_REST_MS)
        self._build_rest.timeout.connect(self._build_rested)
        self.reconstruct_panel.build_slider.sliderReleased.connect(self._build_rest.start)
        self.compare_panel.load_requested.connect(self.ask_load_truth)
        self.session.fit_changed.connect(self.reconstruct_panel.show_result)
        self.session.truth_changed.connect(
            lambda truth: self.compare_panel.show_comparison(truth[0], None)
        )
        self.resize(1400, 900)
        self._update_title()

        from workbench.qt.autosave import install_autosave

        self.autosaver = install_autosave(self)  # snapshots of unsaved work (crash recovery)

    # ------------------------------------------------------------ results (the session's)
    @property
    def fit(self) -> jobs.FitResult | None:
        """The last fitted face (:attr:`Session.fit`)."""
        return self.session.fit

    @property
    def preview(self) -> jobs.DowelPreview | None:
        """The dowel plan drawn (:attr:`Session.preview`)."""
        return self.session.preview

    @property
    def truth(self) -> tuple[str, Any] | None:
        """The true skin ``(name, mesh)`` (:attr:`Session.truth`)."""
        return self.session.truth

    @property
    def comparison(self) -> Any:
        """The last comparison with the true skin (:attr:`Session.comparison`)."""
        return self.session.comparison

    # ------------------------------------------------------------ file actions (the tool's)
    def open_skull(self, path: str | Path, units: str = "auto", scale: float | None = None) -> None:
        self.files.open_skull(path, units, scale)

    def open_ct(
        self,
        path: str | Path,
        tissue: str = "bone",
        iso: float | None = None,
        *,
        volume: Any = None,
        finished: Callable[[bool], None] | None = None,
    ) -> bool:
        return self.files.open_ct(path, tissue, iso, volume=volume, finished=finished)

    def open_ct_dialog(self, path: str | Path) -> Any:
        return self.files.open_ct_dialog(path)

    def open_case(self, path: str | Path) -> None:
        self.files.open_case(path)

    def replace_case(self, opened: OpenedCase, path: Path | None) -> None:
        self.files.replace_case(opened, path)

    def may_discard(self) -> bool:
        """True if the open case may be replaced (saved, discarded, or clean)."""
        return self.files.may_discard()

    def save(self) -> bool:
        return self.files.save()

    def save_to(self, path: str | Path) -> bool:
        return self.files.save_to(path)

    def ask_save_as(self) -> bool:
        return self.files.ask_save_as()

    def export_to(self, folder: str | Path) -> None:
        self.files.export_to(folder)

    @property
    def exported(self) -> dict[str, Path]:
        """The files of the last export (:attr:`FileTool.exported`)."""
        return self.files.exported

    @property
    def ct_dialog(self) -> Any:
        """The last CT import dialog opened, or None."""
        return self.files.ct_dialog

    def ask_open_skull(self) -> None:
        self.files.ask_open_skull()

    def ask_open_ct(self) -> None:
        self.files.ask_open_ct()

    def ask_open_case(self) -> None:
        self.files.ask_open_case()

    def ask_export(self) -> None:
        self.files.ask_export()

    def ask_load_truth(self) -> None:
        self.files.ask_load_truth()

    def ask_screenshot(self) -> None:
        self.files.ask_screenshot()

    # ------------------------------------------------------------ fit scan (the tool's)
    def open_scan(self, path: str | Path, units: str = "auto", scale: float | None = None) -> None:
        """Open a face scan in the Fit scan tool (worker; the case is not touched)."""
        self.docks["fit_scan"].raise_()
        self.scan_fit.open_scan(path, units, scale)

    def fit_scan(self) -> None:
        """Fit the reference head to the open scan (worker, progress, cancel)."""
        self.docks["fit_scan"].raise_()
        self.scan_fit.fit()

    # ------------------------------------------------------------ animate (the tool's)
    def show_animate(self, expression: str | None = None, weight: float = 1.0) -> None:
        """Bring the Animate dock to the front (loading its head); optionally pick a preset."""
        dock = self.docks["animate"]
        dock.show()
        dock.raise_()
        if expression is not None:
            panel = self.animate_panel
            panel.intensity.setValue(round(100 * weight))
            panel.expression.setCurrentText(expression)
        self.animate.ensure_loaded()

    def show_age(
        self,
        to_age: float | None = None,
        from_age: float | None = None,
        sex: str | None = None,
        *,
        reconstructed: bool = False,
    ) -> None:
        """Bring the Age progression dock to the front (loading its head); optionally set
        the source age and sex and the target age (years).  The head: the reference of
        ``sex``, or with ``reconstructed`` the case's reconstructed head (aged with the
        norms of the case's sex)."""
        dock = self.docks["age"]
        dock.show()
        dock.raise_()
        panel = self.age_panel
        if reconstructed and self.session.fit is not None:
            panel.source.setCurrentText("Reconstructed head (this case)")
        elif sex is not None:
            panel.source.setCurrentText(f"Reference {sex}")
        if from_age is not None:
            panel.from_age.setValue(from_age)
        if to_age is not None:
            panel.target.setValue(round(to_age))
            self.age.request(to_age)
        self.age.ensure_loaded()

    def _age_in_front(self) -> bool:
        dock = self.docks.get("age")
        return bool(
            dock is not None
            and self.age.source is not None
            and dock.isVisible()
            and not dock.visibleRegion().isEmpty()
        )

    def _animate_in_front(self) -> bool:
        dock = self.docks.get("animate")
        return bool(
            dock is not None
            and self.animate.animator is not None
            and dock.isVisible()
            and not dock.visibleRegion().isEmpty()
        )

    # ------------------------------------------------------------ messages
    def status(self, text: str) -> None:
        self.status_label.setText(text)

    def status_text(self) -> str:
        return self.status_label.text()

    def show_error(self, what: str, exc: BaseException) -> None:
        """A readable message (never a traceback); the case stays as it was."""
        text, _details = dialogs.error_text(what, exc)
        self.errors.append(text)
        self.status(text.replace("\n\n", " — ").splitlines()[0])
        if self.interactive:
            dialogs.show_error(self, what, exc)

    def _on_busy(self, busy: bool, text: str) -> None:
        """Progress bar and the job's text; when idle again, the message from before."""
        self.progress.setVisible(busy)
        if busy:
            self.progress.setRange(0, 0)  # indeterminate until the job reports progress
            if not self._busy_text:
                self._status_before = self.status_label.text()
            self._busy_text = text
            self.status(text)
            return
        if self._busy_text and self.status_label.text() == self._busy_text:
            self.status(self._status_before)  # nothing newer was said meanwhile
        self._busy_text = ""

    def _update_title(self) -> None:
        self.setWindowTitle(self.document.title)
        stack: Any = self.scan_fit.landmarks if self._scan_fit_undo() else self.document.stack
        undo, redo = self.actions_by_id["undo"], self.actions_by_id["redo"]
        undo.setEnabled(stack.can_undo)
        redo.setEnabled(stack.can_redo)
        undo.setText(f"&Undo {stack.undo_text}" if stack.can_undo else "&Undo")
        redo.setText(f"&Redo {stack.redo_text}" if stack.can_redo else "&Redo")

    # ------------------------------------------------------------ edit actions
    def _scan_fit_undo(self) -> bool:
        """Undo/redo work on the scan's placed landmarks (the Fit scan dock is in front
        with a scan open), else on the case (see :mod:`workbench.qt.scan_fit_ops`)."""
        dock = self.docks.get("fit_scan")
        return bool(
            dock is not None
            and self.scan_fit.has_scan
            and dock.isVisible()
            and not dock.visibleRegion().isEmpty()
        )

    def undo(self) -> None:
        if self._scan_fit_undo():
            self.scan_fit.undo()
        else:
            self.document.undo()

    def redo(self) -> None:
        if self._scan_fit_undo():
            self.scan_fit.redo()
        else:
            self.document.redo()

    def mark_absent(self) -> None:
        self.landmarks_panel.mark_absent()

    def select_next_missing(self) -> None:
        self.landmarks_panel.select_next_missing()

    def reset_view(self) -> None:
        if self._animate_in_front():  # the animated head: look at its face
            self.animate.reset_camera()
            return
        if self._age_in_front():  # the source and aged heads: look at their faces
            self.age.reset_camera()
            return
        if self.document.case.specimen.mesh is None and self.scan_fit.has_scan:
            self.scan_fit.reset_camera()  # only a scan is shown: look at its face
            return
        axes = jobs.view_axes(self.document.case)
        self.scene.reset_camera(*(axes or (None, None)))

    def cancel_drag(self) -> None:
        """Esc: end a landmark or guide drag without moving anything."""
        self.drags.cancel_drag()
        self.scan_fit.cancel_drag()

    # ------------------------------------------------------------ landmark actions (the tool's)
    def on_pick(self, point: Any) -> None:
        """A click on the skull at ``point`` (mm): place the selected landmark there."""
        self.landmarks.on_pick(point)

    def suggest_landmarks(self) -> None:
        self.landmarks.suggest_landmarks()

    def snap_selected(self) -> None:
        self.landmarks.snap_selected()

    @property
    def drag_timings(self) -> list[float]:
        """Seconds per computed drag preview (:attr:`DragTool.drag_timings`)."""
        return self.drags.drag_timings

    # ------------------------------------------------------------ case → scene
    def _on_case_replaced(self) -> None:
        self.session.clear_fit()  # the reconstruct panel follows (fit_changed)
        self.show_skull()
        self.scene.clear("face")
        self.scene.clear("muscles")
        self.scene.clear("guides")
        self.scene.clear("dowels")
        self.guide_view.fit_changed()
        self.dowels_panel.show_plan(None)
        self.landmarks.draw_landmarks()
        self.reset_view()
        self.schedule_dowels()

    def _on_part(self, part: str) -> None:
        if part == "specimen":
            self.show_skull()
        if part == "landmarks":
            self.landmarks.draw_landmarks()
        if part in FIT_PARTS:
            self.schedule_dowels()
            if self.session.fit is not None and self.reconstruct_panel.auto_refit.isChecked():
                self.reconstruct()

    def _on_layer_changed(self, layer: str) -> None:
        if layer == "face":  # the panel's opacity slider follows the Layers dock
            self.reconstruct_panel.show_opacity(self.scene.opacity["face"])

    def user_toggled_guide_view(self, on: bool) -> None:
        """The View-menu toggle: remember a deliberate close (no reopening on the next fit)."""
        self.guide_view.closed_by_user = not on
        self.show_guide_view(on)

    def show_guide_view(self, on: bool, draw: bool = True) -> None:
        """Show or hide the second view (guides, orthographic) beside the 3D view.

        ``draw=False`` shows it without drawing (the caller fills it later).
        """
        if on and not draw:
            self.guide_view.stale = False  # not even what it missed while hidden
        self.guide_view.setVisible(bool(on))
        action = self.actions_by_id.get("guide_view")
        if action is not None and action.isChecked() != bool(on):
            action.blockSignals(True)
            action.setChecked(bool(on))
            action.blockSignals(False)
        if on and draw:
            self.guide_view.refresh(reset_camera=True)

    def _skull_actor(self) -> Any:
        actors = self.scene.actors("skull")
        return actors[0] if actors else None

    def _skull_surface(self) -> Any:
        """The skull's full-resolution ``vtkPolyData`` as drawn (picking, level of detail)."""
        return self._skull_poly

    def show_skull(self) -> None:
        """Draw the case's skull and prepare its light copy for interaction."""
        import pyvista as pv

        self.detail.set_skull(None, None)
        actor = self.scene.show_skull(self.document.case.specimen.mesh)
        self._skull_poly = None if actor is None else pv.wrap(actor.GetMapper().GetInput())
        self.detail.set_skull(actor, self._skull_poly, self.document.case.specimen.mesh)

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
        skull, settings = case.specimen.mesh, jobs.depth_settings(case)
        self.runner.submit(
            "dowels",
            "Planning dowels …",
            lambda: jobs.preview_dowels(skull, lms, settings),
            self._show_dowels,
            self._dowels_failed,
        )

    def _show_dowels(self, preview: jobs.DowelPreview) -> None:
        self.session.set_preview(preview)
        self.scene.show_dowels(preview.origins, preview.tips)
        self.dowels_panel.show_plan(preview)

    def _dowels_failed(self, exc: BaseException) -> None:
        self.session.set_preview(None)
        self.scene.clear("dowels")
        self.dowels_panel.show_plan(None, dialogs.error_text("No dowels", exc)[0])

    # ------------------------------------------------------------ reconstruct
    def reconstruct(self) -> None:
        """Fit the face in the worker (guides and ensemble as the panel says)."""
        case = self.document.case
        if case.specimen.mesh is None:
            self.status("Open a skull first.")
            return
        panel = self.reconstruct_panel
        try:  # the snapshot the worker fits; the user may go on editing the case
            inputs = jobs.fit_inputs(
                case, use_guides=panel.use_guides.isChecked(), ensemble=panel.ensemble.value()
            )
        except Exception as exc:  # noqa: BLE001 - shown as a readable message
            self.show_error("The stored guides are not usable", exc)
            return
        self.runner.submit(
            "fit",
            "Reconstructing the face …",
            lambda: jobs.fit_face(inputs),
            self._show_fit,
            lambda exc: self.show_error("Could not reconstruct the face", exc),
        )

    def _show_fit(self, fit: jobs.FitResult) -> None:
        self.session.set_fit(fit)  # the reconstruct panel follows (fit_changed)
        reg = fit.recon.registration
        check = {} if reg is None else reg.figures.get("self_check") or {}
        if check.get("outcome") == "check":
            # the self-check's doubt first (issue 28): the user confirms before using the face
            self.status(f"CHECK: {check['reasons'][0]} (face fitted; confirm the orientation)")
        else:
            self.status(f"Face fitted in {self.runner.timings.get('fit', 0):.1f} s")
        if not self.guide_view.isVisible() and not self.guide_view.closed_by_user:
            # the first fit opens the guide view.  Both views then repaint
            # in one pass (the main view narrows, the new one appears), so
            # open it while both are cheap to draw (the new one empty, the
            # main one without the face) and draw the fit after that paint
            self.show_guide_view(True, draw=False)
            self.scene.after_paint(lambda f=fit: self._draw_fit(f), render=False)
        else:
            self._draw_fit(fit)

    def _draw_fit(self, fit: jobs.FitResult) -> None:
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

    def _show_fit_in_guide_view(self, fit: jobs.FitResult) -> None:
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
        if scalars is None:
            self.scene.show_face(face)
        else:
            self.scene.show_face(face, scalars, title)

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
        segments, points = jobs.guide_geometry(fit)
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
            lambda exc: self.show_error(f"Could not read {path.name}", exc),
        )

    def _truth_loaded(self, name: str, mesh: Any) -> None:
        self.session.set_truth(name, mesh)  # the compare panel follows (truth_changed)
        self.scene.show_truth(mesh)
        self.docks["compare"].raise_()
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
            lambda exc: self.show_error("Could not compare", exc),
        )

    def _show_comparison(self, comparison: Any) -> None:
        truth_loaded = self.session.truth
        if truth_loaded is None:  # a comparison is only started with a true skin
            raise RuntimeError("a comparison arrived without a true skin")
        self.session.set_comparison(comparison)
        name, truth = truth_loaded
        self.scene.show_truth(truth, comparison.truth_vertex_values())
        self.compare_panel.show_comparison(name, comparison)
        self.status(
            f"Compared with {name}: mean |distance| "
            f"{comparison.figures['mean_abs_mm']:.2f} mm "
            f"({self.runner.timings.get('compare', 0):.1f} s)"
        )

    # ------------------------------------------------------------ pictures and closing
    @property
    def busy(self) -> bool:
        """A worker job is pending, or drawing is queued behind the next paint."""
        return self.runner.busy or self.scene.paint_work_pending

    def wait_idle(self, timeout_s: float = 120.0) -> bool:
        """Process events until nothing is pending (scripts and ``--screenshot``)."""
        import time

        end = time.monotonic() + timeout_s
        while self.busy and time.monotonic() < end:
            QApplication.processEvents()
            time.sleep(0.01)
        QApplication.processEvents()
        return not self.busy

    def view_rect(self) -> QRect:
        """The 3D view's rectangle in window coordinates (pictures, tests)."""
        return QRect(self.plotter.mapTo(self, QPoint(0, 0)), self.plotter.size())

    def save_screenshot(self, path: str | Path) -> Path:
        """Render and grab the whole window (3D view included under xcb) to a PNG."""
        QApplication.processEvents()
        self.scene.render_now()
        QApplication.processEvents()
        path = Path(path)
        if not self.grab().save(str(path)):
            raise OSError(f"could not write {path}")
        return path

    def closeEvent(self, event: Any) -> None:  # noqa: N802 - Qt name
        if self.interactive and not self.may_discard():
            event.ignore()
            return
        self.autosaver.close()  # a clean close: the snapshot of unsaved work goes
        self.runner.shutdown()
        self.picker.detach()
        self.scan_fit.detach()
        self.animate.detach()
        self.age.detach()
        self.detail.detach()
        self.scene.detach()
        self.guide_view.close_view()
        self.plotter.close()
        super().closeEvent(event)


def _scrolling(panel: QWidget) -> QScrollArea:
    """``panel`` in a scroll area: a long panel never forces the window taller."""
    area = QScrollArea()
    area.setWidget(panel)
    area.setWidgetResizable(True)
    area.setFrameShape(QScrollArea.Shape.NoFrame)
    return area
