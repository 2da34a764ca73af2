"""The workbench main window: it assembles a 3D view, the tool docks, menus, status bar.

Wiring (built in this order by ``__init__``'s ``_build_*`` steps)::

    MainWindow
    ├── Document            case + CommandStack (the one undo stack) + file; Qt signals
    ├── Session             derived results (fit, dowel preview, true skin, comparison)
    ├── TaskRunner          worker threads; results come back on the GUI thread
    ├── FileTool            open, save, export (file_ops)
    ├── QtInteractor        central 3D view (pyvistaqt)
    │   ├── SceneView       named layers: skull, landmarks, dowels, guides, muscles, face, truth
    │   └── ClickPicker     click (not drag) on the skull → PlaceLandmark
    ├── tools (qt/tools)    LandmarkTool (draw, place, suggest, snap), DragTool (live
    │                       drags), ScanFitTool (a face scan fitted by the scan-fit
    │                       service, its landmarks; own picker), AnimateTool (the
    │                       animation service's Animator, live skin), AgeTool (the age
    │                       service under a target-age slider), ReconstructTool (dowel
    │                       plan, face fit and its drawing, comparison), AppearanceTool
    │                       (the face's chosen colours, painted on the face layer)
    ├── panels              LandmarksPanel, DowelsPanel, ReconstructPanel, ComparePanel,
    │                       ScanFitPanel, AnimatePanel, AgePanel, AppearancePanel (docks);
    │                       LayersPanel below them (visibility + opacity per layer)
    ├── GuideView           second view: guides over the session's fit (drags → DragTool)
    └── menus               actions.ACTIONS (File, Edit, Tools, View + layer toggles)

The window holds no geometry logic and no tool's logic: it builds the pieces,
connects them, and keeps thin methods (``reconstruct``, ``open_scan``,
``show_age`` ...) that the menus, scripts and tests call and the tools carry
out.  Edits are commands pushed on the document's stack, computations are
:mod:`workbench.services.reconstruction.case_steps` (or a tool's worker) functions run in the worker, and
their results are drawn.  Units mm; the scene is in the specimen's input frame
(the skull file's coordinates).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import QPoint, QRect, Qt
from PySide6.QtGui import QKeySequence, QShortcut
from PySide6.QtWidgets import (
    QApplication,
    QDockWidget,
    QLabel,
    QMainWindow,
    QProgressBar,
    QPushButton,
    QScrollArea,
    QSplitter,
    QTabBar,
    QWidget,
)

from workbench.io.catalogue import load_catalogue
from workbench.qt import dialogs, gc_guard
from workbench.qt.actions import (
    AGE_ACTIONS,
    ANIMATE_ACTIONS,
    SCAN_FIT_ACTIONS,
    add_tool_actions,
    build_menus,
)
from workbench.qt.document import Document
from workbench.qt.file_ops import FileTool
from workbench.qt.guide_view import GuideView
from workbench.qt.lod import InteractiveDetail
from workbench.qt.panels.age_panel import AgePanel
from workbench.qt.panels.animate_panel import AnimatePanel
from workbench.qt.panels.appearance_panel import AppearancePanel
from workbench.qt.panels.compare_panel import ComparePanel
from workbench.qt.panels.dowels_panel import DowelsPanel
from workbench.qt.panels.landmarks_panel import LandmarksPanel
from workbench.qt.panels.layers_panel import LayersPanel
from workbench.qt.panels.reconstruct_panel import ReconstructPanel
from workbench.qt.panels.scan_fit_panel import ScanFitPanel
from workbench.qt.picking import ClickPicker
from workbench.qt.scene import SceneView, case_anatomy
from workbench.qt.session import Session
from workbench.qt.tools.age.tool import AgeTool
from workbench.qt.tools.animate.tool import AnimateTool
from workbench.qt.tools.appearance import AppearanceTool
from workbench.qt.tools.drags import DragTool
from workbench.qt.tools.landmarks import LandmarkTool
from workbench.qt.tools.reconstruct import FIT_PARTS, ReconstructTool
from workbench.qt.tools.scan_fit.tool import ScanFitTool
from workbench.qt.workers import TaskRunner, preload, show_fraction
from workbench.services.reconstruction import case_steps

if TYPE_CHECKING:
    from workbench.services.case.case_setup import OpenedCase


#: worker channels the status bar's Cancel stops, with what the status line calls them
CANCELLABLE = {"fit": "the fit", "suggest": "the landmark suggestion"}


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

        self._build_views(auto_update)
        self._build_skull_tools()
        self._build_dock_tools()
        self._build_docks()
        self._build_guide_view()
        self.reconstruction = ReconstructTool(
            self.document,
            self.session,
            self.runner,
            self.scene,
            self.plotter,
            self.detail,
            self.guide_view,
            self.reconstruct_panel,
            self.dowels_panel,
            self.compare_panel,
            self,
            parent=self,
        )
        self._build_menus()
        self._build_status_bar()
        self._connect()
        self.resize(1400, 900)
        self._update_title()

        from workbench.qt.autosave import install_autosave

        self.autosaver = install_autosave(self)  # snapshots of unsaved work (crash recovery)

    def _build_views(self, auto_update: bool | float) -> None:
        """The central 3D view (and the splitter the guide view joins later), its layers."""
        from pyvistaqt import QtInteractor

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

    def _build_skull_tools(self) -> None:
        """The case's panels and the tools that edit the skull: landmarks, drags, picking."""
        self.landmarks_panel = LandmarksPanel(self.document, self.catalogue)
        self.dowels_panel = DowelsPanel(self.document)
        self.reconstruct_panel = ReconstructPanel(self.document)
        self.compare_panel = ComparePanel()
        self.landmarks = LandmarkTool(
            self.document,
            self.scene,
            self.catalogue,
            self.landmarks_panel,
            self.runner,
            self,
            self.session,
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

    def _build_dock_tools(self) -> None:
        """The tools with a view of their own: scan fit, animate, age progression."""
        self.scan_fit_panel = ScanFitPanel()
        self.scan_fit = ScanFitTool(
            self.scan_fit_panel,
            self.scene,
            self.plotter,
            self.runner,
            self,
            skull_picker=self.picker,
            document=self.document,
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
        self.appearance_panel = AppearancePanel()  # the face's chosen colours (artistic)
        self.appearance = AppearanceTool(
            self.appearance_panel,
            self.document,
            self.session,
            self.scene,
            self,
            parent=self,
            runner=self.runner,
        )

    def _build_docks(self) -> None:
        """The tool panels as tabbed docks on the right, the Layers dock below them."""
        self.docks: dict[str, QDockWidget] = {}
        for key, title, panel in (
            ("landmarks", "Landmarks", self.landmarks_panel),
            ("dowels", "Dowels", self.dowels_panel),
            ("reconstruct", "Reconstruct", self.reconstruct_panel),
            ("compare", "Compare", self.compare_panel),
            ("fit_scan", "Scan fit", self.scan_fit_panel),
            ("animate", "Animate", self.animate_panel),
            ("age", "Age", self.age_panel),
            ("appearance", "Appearance", self.appearance_panel),
        ):
            dock = QDockWidget(title, self)
            dock.setObjectName(f"dock_{key}")
            dock.setWidget(_scrolling(panel))
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock)
            if self.docks:
                self.tabifyDockWidget(next(iter(self.docks.values())), dock)
            self.docks[key] = dock
        self.docks["landmarks"].raise_()
        # the tabs' names whole (issue 33: they read "Sku… D… C…"): arrows scroll the tab
        # row where it is narrower than the names
        for bar in self.findChildren(QTabBar):
            bar.setElideMode(Qt.TextElideMode.ElideNone)
            bar.setUsesScrollButtons(True)
        self.layers_panel = LayersPanel(self.scene)
        self.docks["layers"] = dock = QDockWidget("Layers", self)
        dock.setObjectName("dock_layers")
        dock.setWidget(_scrolling(self.layers_panel))
        # below the tool tabs: layers stay in reach whichever tool is open
        self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, dock, Qt.Orientation.Vertical)
        self.resizeDocks([self.docks["landmarks"], dock], [620, 230], Qt.Orientation.Vertical)
        self.resizeDocks([self.docks["landmarks"]], [420], Qt.Orientation.Horizontal)

    def _build_guide_view(self) -> None:
        """The second view (guides over the fit, orthographic), hidden until the first fit."""
        self.guide_view = GuideView(
            self.session, self.runner, self.scene, self.reconstruct_panel, self.drags
        )
        self.drags.attach(self.picker, self.guide_view)
        self.scene.also_tune(self.guide_view.plotter)
        self.views.addWidget(self.guide_view)
        self.views.setStretchFactor(0, 3)
        self.views.setStretchFactor(1, 2)
        self.guide_view.hide()  # shown with the first fit, or from the View menu

    def _build_menus(self) -> None:
        self.actions_by_id = build_menus(self)
        self.actions_by_id.update(add_tool_actions(self, self.scan_fit, SCAN_FIT_ACTIONS))
        self.actions_by_id.update(add_tool_actions(self, self, ANIMATE_ACTIONS))
        self.actions_by_id.update(add_tool_actions(self, self, AGE_ACTIONS))

    def _build_status_bar(self) -> None:
        self.status_label = QLabel("Open a skull mesh, a CT or a case (File menu).")
        self.progress = QProgressBar()
        self.progress.setRange(0, 0)
        self.progress.setMaximumWidth(180)
        self.progress.hide()
        self.statusBar().addWidget(self.status_label, 1)
        self._busy_text, self._status_before = "", ""
        self.statusBar().addPermanentWidget(self.progress)
        # stops a long job that reports its progress (a fit, a suggestion); see cancel_jobs
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setToolTip("Stop the fit or suggestion running (Esc in a drag)")
        self.cancel_button.clicked.connect(self.cancel_jobs)
        self.cancel_button.hide()
        self.statusBar().addPermanentWidget(self.cancel_button)

    def _connect(self) -> None:
        """The window's own reactions: the case to the scene, docks to their tools, status."""
        self.document.case_replaced.connect(self._on_case_replaced)
        self.document.part_changed.connect(self._on_part)
        self.document.part_changed.connect(
            lambda part: self.guide_view.refresh() if part == "guides" else None
        )
        self.document.stack_changed.connect(self._update_title)
        self.docks["animate"].visibilityChanged.connect(self.animate.set_active)
        self.docks["age"].visibilityChanged.connect(self.age.set_active)
        self.docks["fit_scan"].visibilityChanged.connect(self.scan_fit.set_active)
        # the session's own heads offered to the Animate and Age docks (issue 33): the head
        # fitted to a scan, and the aged head shown (as the command line takes their packs)
        self.scan_fit.fitted.connect(self.age.scan_changed)
        self.scan_fit.fitted.connect(lambda head: self.animate.offer_head("scan", head))
        self.age.shown.connect(self._offer_aged_head)
        self.session.fit_changed.connect(lambda fit: self.age.fit_changed(fit is not None))
        # the case's own head in the Animate dock once a face is fitted (issue 33)
        self.session.fit_changed.connect(
            lambda fit: self.animate.fit_changed(None if fit is None else fit.recon.head)
        )
        self.runner.busy_changed.connect(self._on_busy)
        self.runner.progress_changed.connect(
            lambda _channel, step, f: show_fraction(self.progress, f, step)
        )
        self.landmarks_panel.selection_changed.connect(lambda _c: self.landmarks.draw_landmarks())
        self.landmarks_panel.suggest_requested.connect(self.landmarks.suggest_landmarks)
        self.landmarks_panel.snap_requested.connect(lambda _code: self.landmarks.snap_selected())
        self.reconstruct_panel.opacity_changed.connect(lambda v: self.scene.set_opacity("face", v))
        self.scene.layer_changed.connect(self._on_layer_changed)
        self.compare_panel.load_requested.connect(self.ask_load_truth)

    # ------------------------------------------------------------ results (the session's)
    @property
    def fit(self) -> case_steps.FitResult | None:
        """The last fitted face (:attr:`Session.fit`)."""
        return self.session.fit

    @property
    def preview(self) -> case_steps.DowelPreview | None:
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

    def export_to(self, folder: str | Path, force: bool = False) -> bool:
        return self.files.export_to(folder, force)

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

    def ask_case_details(self) -> None:
        """File ▸ Case details…: the examiner and the notes (:mod:`workbench.qt.case_details`)."""
        from workbench.qt.case_details import open_case_details

        self.case_details = open_case_details(self)

    def ask_load_truth(self) -> None:
        self.files.ask_load_truth()

    def ask_screenshot(self) -> None:
        self.files.ask_screenshot()

    def show_portrait(self) -> None:
        """View ▸ Portrait…: the fitted face as appeal pictures (:mod:`workbench.qt.portrait_dialog`)."""
        from workbench.qt.portrait_dialog import open_portrait

        self.portrait = open_portrait(self)

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
            panel.select_expression(expression)
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
        """Say ``text`` in the status line; it stays there after the jobs running end."""
        if self._busy_text and text != self._busy_text:
            self._status_before = text  # what to show again when the jobs are done
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

    def cancel_jobs(self) -> None:
        """Stop the running fit and suggestion (the face and landmarks shown stay)."""
        stopped = [ch for ch in CANCELLABLE if self.runner.cancel(ch)]
        if stopped:
            self.status(f"Cancelled: {', '.join(CANCELLABLE[ch] for ch in stopped)}.")

    def _on_busy(self, busy: bool, text: str) -> None:
        """Progress bar and the job's text; when idle again, the message from before."""
        self.cancel_button.setVisible(busy and any(map(self.runner.is_running, CANCELLABLE)))
        self.progress.setVisible(busy)
        if busy:
            self.progress.setRange(0, 0)  # indeterminate until the job reports progress
            if not self._busy_text:
                self._status_before = self.status_label.text()
            self._busy_text = text
            self.status_label.setText(text)
            return
        if self._busy_text and self.status_label.text() == self._busy_text:
            self.status(self._status_before)  # nothing newer was said meanwhile
        self._busy_text = ""

    def _update_title(self) -> None:
        self.setWindowTitle(self.document.title)
        stack = self.document.stack  # the one undo stack: case edits and scan placements
        undo, redo = self.actions_by_id["undo"], self.actions_by_id["redo"]
        undo.setEnabled(stack.can_undo)
        redo.setEnabled(stack.can_redo)
        undo.setText(f"&Undo {stack.undo_text}" if stack.can_undo else "&Undo")
        redo.setText(f"&Redo {stack.redo_text}" if stack.can_redo else "&Redo")

    # ------------------------------------------------------------ edit actions
    def undo(self) -> None:
        """Edit ▸ Undo: the last step of the one undo stack (a case edit or, see
        :mod:`workbench.qt.tools.scan_fit`, a placement on the scan)."""
        self.document.undo()

    def redo(self) -> None:
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
        # the face from the front, the subject's right on the viewer's left (a mirror-image
        # file is shown reflected: one handedness with the guide view and the report)
        self.scene.reset_camera(case_anatomy(self.document.case))

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
        if part == "appearance" and self.session.fit is not None:
            self.draw_face()  # the eyes take the chosen iris colour
        if part in FIT_PARTS:
            self.schedule_dowels()
            if self.session.fit is not None and self.reconstruct_panel.auto_refit.isChecked():
                self.reconstruction.reconstruct(after_edit=True)

    def _offer_aged_head(self, age: int) -> None:
        step = self.age.step
        head = None if step is None else step.result.head
        self.animate.offer_head("aged", head, f"The aged head ({age} y)")

    def restore_fit(self, stored: Any) -> None:
        """Show the face a reopened case keeps (the Reconstruct tool's ``restore``)."""
        self.reconstruction.restore(stored)

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

    # ------------------------------------------------------------ reconstruct (the tool's)
    def schedule_dowels(self) -> None:
        self.reconstruction.schedule_dowels()

    def reconstruct(self) -> None:
        """Fit the face in the worker (guides and ensemble as the panel says)."""
        self.reconstruction.reconstruct()

    def draw_face(self) -> None:
        self.reconstruction.draw_face()

    def draw_muscles(self) -> None:
        self.reconstruction.draw_muscles()

    def draw_guides(self) -> None:
        self.reconstruction.draw_guides()

    def show_build(self, z: float) -> None:
        self.reconstruction.show_build(z)

    def load_truth(self, path: str | Path, scale: float | None = None) -> None:
        self.reconstruction.load_truth(path, scale)

    def compare(self) -> None:
        self.reconstruction.compare()

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
        self.appearance.detach()
        self.detail.detach()
        self.files.gui_call.close()
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
