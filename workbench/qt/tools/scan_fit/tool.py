"""The "Fit scan" tool's controller: the dock, the worker's jobs, drawing and picking on the scan.

See :mod:`workbench.qt.tools.scan_fit` for what the tool does; the worker side is
:mod:`~workbench.qt.tools.scan_fit.work`; the scan, skin and markers are drawn with
:mod:`workbench.render.visuals`.  Frames and units: mm, the scan's own frame.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from PySide6.QtCore import QObject, QTimer, Signal

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.errors import InputError, UnitsError, WorkbenchError
from workbench.qt.document import Document
from workbench.qt.gui_call import GuiCall
from workbench.qt.tools.common import CaseLayersAside, folder_is_free
from workbench.qt.tools.scan_fit.state import (
    EditScanLandmarks,
    FitView,
    OpenedScan,
    ScanFitSettings,
    ScanLandmarks,
)
from workbench.qt.tools.scan_fit.work import read_scan, run_scan_fit, save_pack
from workbench.render.visuals import face, markers
from workbench.render.visuals.scalar_bars import set_bar_visible

if TYPE_CHECKING:
    from PySide6.QtWidgets import QWidget

    from workbench.core.landmarks import LandmarkSet
    from workbench.io.catalogue import LandmarkCatalogue
    from workbench.qt.panels.scan_fit_panel import ScanFitPanel
    from workbench.qt.picking import ClickPicker
    from workbench.qt.scene import SceneView
    from workbench.qt.workers import TaskRunner
    from workbench.services.scan_fit.settings import ScanFit

#: the worker channel of fits and saves (a newer job supersedes the older)
CHANNEL = "scan_fit"
#: distance colouring of the scan (mm)
DISTANCE_RANGE_MM = (0.0, 2.5)
DISTANCE_TITLE = "scan to fitted skin mm"
#: landmark marker colours by state
STATE_COLOURS = {
    "placed": (0.10, 0.75, 0.25),
    "guess": (1.0, 0.55, 0.0),
    "over hole": (0.62, 0.42, 0.95),
}
MARKER_PX = 10.0


class ScanFitHost(Protocol):
    """What the tool uses of the window: status line, readable errors, dialogs' parent."""

    messages: list[str]
    interactive: bool

    def status(self, text: str) -> None: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...

    def window(self) -> QWidget: ...


class ScanFitTool(QObject):
    """The "Fit scan" tool: see :mod:`workbench.qt.tools.scan_fit`.

    ``document`` (default: ``host.document``, else a document of the tool's own) holds
    the undo stack the placements are pushed on: the window's one stack.
    """

    #: the head fitted to the scan (head frame, mm) once a fit is shown; None when a new
    #: scan replaces it (the Age and Animate docks offer it)
    fitted = Signal(object)

    def __init__(
        self,
        panel: ScanFitPanel,
        scene: SceneView,
        plotter: Any,
        runner: TaskRunner,
        host: ScanFitHost,
        *,
        skull_picker: ClickPicker | None = None,
        catalogue: LandmarkCatalogue | None = None,
        document: Document | None = None,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        from workbench.qt.picking import ClickPicker

        self.panel = panel
        self.scene = scene
        self.plotter = plotter
        self.runner = runner
        #: the pack's report pictures are drawn on the GUI thread (VTK), the rest in the worker
        self.gui_call = GuiCall()
        self.host = host
        self.catalogue = catalogue
        self.skull_picker = skull_picker
        self.scan: OpenedScan | None = None
        self.view: FitView | None = None
        self.landmarks = ScanLandmarks(on_change=self._changed)
        if document is None:
            document = getattr(host, "document", None) or Document(host.show_error, self)
        self.document: Document = document
        document.stack_changed.connect(self._show_history)
        self._show_history()
        self.saved: list[Path] = []
        self._actors: dict[str, list[Any]] = {}
        #: the dock is in front (the window follows its visibility; alone, always)
        self.active = True
        self._aside = CaseLayersAside(scene)
        self._scan_poly: Any = None
        self._on_scan_skin: Any = None
        #: the placed landmarks the last fit started with (Save pack reuses that fit)
        self._fit_placed: LandmarkSet | None = None
        self._drag: tuple[str, np.ndarray] | None = None
        self._drag_scheduled = False
        self.picker: ClickPicker | None = ClickPicker(
            plotter,
            self._scan_actor,
            self.on_pick,
            target_surface=lambda: self._scan_poly,
            grab_target=self.grab_target,
            on_drag=self.on_drag,
            on_drag_end=self.on_drag_end,
        )
        self.picker.enabled = False
        p = panel
        p.open_requested.connect(self.ask_open_scan)
        p.fit_requested.connect(self.fit)
        p.cancel_requested.connect(self.cancel)
        p.save_requested.connect(self.ask_save)
        p.accept_requested.connect(self.accept_selected)
        p.accept_all_requested.connect(self.accept_all)
        p.remove_requested.connect(self.remove_selected)
        p.undo_requested.connect(self.undo)
        p.redo_requested.connect(self.redo)
        p.place_toggled.connect(self.set_placing)
        p.selection_changed.connect(lambda _code: self.draw_landmarks())
        p.visibility_changed.connect(self.set_visible)
        p.opacity_changed.connect(lambda v: self._set_opacity("skin", v))
        p.detail_toggled.connect(lambda _on: self.draw_skin())
        p.scan_colours_changed.connect(lambda _key: self.draw_scan())
        runner.progress_changed.connect(self._on_progress)
        runner.cancelled.connect(lambda ch: self._on_cancelled() if ch == CHANNEL else None)

    # ------------------------------------------------------------ state
    @property
    def has_scan(self) -> bool:
        return self.scan is not None

    @property
    def fit_result(self) -> ScanFit | None:
        return None if self.view is None else self.view.fit

    def settings(self) -> ScanFitSettings:
        from workbench.model.reconstruction_setup import parse_build
        from workbench.qt.panels.build_choice import chosen_build

        p = self.panel
        return ScanFitSettings(
            p.sex_combo.currentText(),
            p.table_combo.currentText() or DEFAULT_DEPTH_TABLE,
            parse_build(chosen_build(p.build_combo)),
        )

    # ------------------------------------------------------------ open
    def ask_open_scan(self) -> None:
        from PySide6.QtWidgets import QFileDialog

        from workbench.qt.file_ops import MESH_FILTER

        name, _ = QFileDialog.getOpenFileName(
            self.host.window(), "Open a face scan (mm, or choose its units)", "", MESH_FILTER
        )
        if name:
            self.open_scan(name, self.panel.units_combo.currentText())

    def open_scan(self, path: str | Path, units: str = "auto", scale: float | None = None) -> None:
        """Read the scan in the worker; then show it (the previous fit and placements go)."""
        path = Path(path)
        self.panel.show_state(f"Reading {path.name} …")
        self.runner.submit(
            "scan_open",
            f"Opening the scan {path.name} …",
            lambda: read_scan(path, units, scale),
            self._scan_opened,
            lambda exc: self._open_failed(path, exc),
        )

    def _open_failed(self, path: Path, exc: BaseException) -> None:
        if isinstance(exc, UnitsError) and self.host.interactive:
            from workbench.qt import dialogs

            factor = dialogs.ask_units(self.host.window(), path.name, exc.problem)
            if factor is not None:
                self.open_scan(path, scale=factor)
                return
        self.panel.show_state(f"Could not open {path.name}.")
        self.host.show_error(f"Could not open the scan {path.name}", exc)

    def _scan_opened(self, scan: OpenedScan) -> None:
        self.runner.cancel(CHANNEL)  # a fit of the previous scan is of no use now
        self.scan, self.view = scan, None
        self.fitted.emit(None)
        self.landmarks.clear(scan.path.name)
        self.panel.show_scan(scan)
        self.panel.show_fit(None)
        self._refresh_landmarks()
        self.draw_scan()
        self._clear("skin")
        self.draw_landmarks()
        self.reset_camera()
        # the scan has its own frame: the case's skull and face are set aside meanwhile
        self._aside.set_aside(self.active)
        n = scan.mesh.n_faces
        carried = ""
        if scan.colours is not None:
            carried = ", textured" if scan.colours.kind == "texture" else ", vertex colours"
        self.host.status(
            f"Scan {scan.path.name}: {n:,} triangles ({scan.factor:g} mm per file unit"
            f"{carried}). Fit it (Fit scan dock) or place 3+ skin landmarks first."
        )
        self.host.messages.extend(scan.messages)
        if scan.colour_note:  # the scan is open; only its colours are missing
            note = f"its colours could not be read ({scan.colour_note})"
            self.panel.show_state(f"Opened; {note}: it is shown and fitted without them.")
            self.host.messages.append(f"{scan.path.name}: {note}")

    # ------------------------------------------------------------ fit
    def fit(self) -> None:
        """Fit the reference head in the worker (seeded by the placed landmarks)."""
        scan = self.scan
        if scan is None:
            self.host.status("Open a scan first (File → Open face scan…).")
            return
        try:
            settings = self.settings()
        except WorkbenchError as exc:
            self.host.show_error("The fit settings are not usable", exc)
            return
        placed = self.landmarks.placed
        self._fit_placed = placed
        if 0 < len(placed) < 3:
            self.host.messages.append(
                f"{len(placed)} landmark(s) placed: 3 or more orient the scan; "
                "the orientation is searched automatically"
            )
        self.panel.set_running(True)
        self.panel.show_state("Fitting …")
        self.runner.submit(
            CHANNEL,
            f"Fitting the reference head to {scan.path.name} …",
            lambda report: run_scan_fit(scan, placed, settings, report),
            self._show_fit,
            lambda exc: self._failed("Could not fit the scan", exc),
            progress=True,
        )

    def cancel(self) -> None:
        self.runner.cancel(CHANNEL)

    def _on_cancelled(self) -> None:
        self.panel.set_running(False)
        self.panel.show_state("Cancelled; nothing changed.")
        self.host.status("Scan fit cancelled.")

    def _on_progress(self, channel: str, step: str, fraction: float) -> None:
        if channel == CHANNEL:
            self.panel.show_state(f"{step} ({fraction * 100:.0f} %)")

    def _failed(self, what: str, exc: BaseException) -> None:
        self.panel.set_running(False)
        self.panel.show_state(f"{what}.")
        self.host.show_error(what, exc)

    def _show_fit(self, view: FitView) -> None:
        self.panel.set_running(False)
        self.view = view
        self.fitted.emit(view.fit.head)
        fig = view.fit.figures
        seconds = self.runner.timings.get(CHANNEL, 0.0)
        self.panel.show_fit(view)
        self.panel.show_state(f"Fitted in {seconds:.1f} s.")
        self._refresh_landmarks()
        self.draw_scan()
        self.draw_skin()
        self.draw_landmarks()
        self.reset_camera()
        self.host.messages.extend(view.fit.warnings)
        if view.colour_note:
            self.panel.show_state(f"Fitted in {seconds:.1f} s; {view.colour_note}.")
            self.host.messages.append(view.colour_note)
        self.host.status(
            f"Scan fitted: {fig.get('face_within_1mm_fraction', 0) * 100:.1f} % of the face "
            f"within 1 mm, {fig.get('fold_overs', 0)} fold-overs ({seconds:.1f} s)"
        )

    # ------------------------------------------------------------ save
    def ask_save(self) -> None:
        """Ask for the pack's folder (a new name is fine), starting in the case file's folder
        (never beside the scan, which is evidence)."""
        from workbench.qt import dialogs

        if self.scan is None:
            self.host.status("Open a scan first.")
            return
        suggested = dialogs.start_folder(self.document.path) / f"{self.scan.path.stem}_fit"
        name = dialogs.ask_new_folder(
            self.host.window(), "Save the fitted head as a pack (a new folder)", suggested
        )
        if name:
            self.save_to(name)

    def _may_replace(self, folder: Path) -> bool:
        """Ask before replacing a non-empty folder (never when not interactive)."""
        from workbench.qt import dialogs

        return self.host.interactive and dialogs.ask_replace_folder(
            self.host.window(), folder, "the fitted pack"
        )

    def save_to(self, folder: str | Path, force: bool = False) -> bool:
        """Fit again and write the pack into ``folder`` (worker); False if refused at once.

        An existing, non-empty ``folder`` is replaced only with ``force`` or
        when the user confirms (the service replaces the folder as a whole).
        """
        scan = self.scan
        if scan is None:
            self.host.status("Open a scan first.")
            return False
        out = Path(folder)
        if not force and not folder_is_free(out):
            if not self._may_replace(out):
                self.host.show_error(
                    "The pack was not saved",
                    InputError(
                        out,
                        "already exists and is not empty; refusing to replace it",
                        "choose a new folder name, or confirm replacing it",
                    ),
                )
                return False
            force = True
        try:
            settings = self.settings()
        except WorkbenchError as exc:
            self.host.show_error("The fit settings are not usable", exc)
            return False
        placed, gui = self.landmarks.placed, self.gui_call
        # the fit shown is written as it is when it is of these landmarks (the pack checks
        # the scan, the landmarks and the settings it was made from)
        same = self._fit_placed is not None and placed.equals(self._fit_placed)
        fitted = self.view.fit if self.view is not None and same else None
        self.panel.set_running(True)
        what = "Writing" if fitted is not None else "Fitting and writing"
        self.panel.show_state(f"{what} {out.name} …")
        self.runner.submit(
            CHANNEL,
            f"Saving the fitted pack {out.name} …",
            lambda report: save_pack(
                scan, out, placed, settings, force=force, report=report, gui=gui, fitted=fitted
            ),
            self._saved,
            lambda exc: self._failed("The pack was not saved", exc),
            progress=True,
        )
        return True

    def _saved(self, result: tuple[FitView, list[Path]]) -> None:
        view, files = result
        self.saved = files
        self._show_fit(view)
        folder = files[0].parent if files else None
        self.panel.show_state(f"Saved {len(files)} files to {folder}.")
        self.host.status(f"Fitted pack saved: {folder} ({len(files)} files)")

    # ------------------------------------------------------------ landmarks
    def _refresh_landmarks(self) -> None:
        scan, view = self.scan, self.view
        codes = scan.codes if scan is not None else ()
        self.panel.show_landmarks(
            codes,
            scan.names if scan is not None else {},
            self.landmarks.placed,
            view.guess if view is not None else {},
            view.over_holes if view is not None else frozenset(),
            view.to_scan_mm if view is not None else {},
            view.confidence if view is not None else {},
        )

    def _changed(self) -> None:
        """The placed landmarks changed (a command was done or undone): redraw."""
        self._refresh_landmarks()
        self.draw_landmarks()

    def _show_history(self) -> None:
        self.panel.show_history(self.document.stack)

    def _push(self, edit: EditScanLandmarks | None) -> bool:
        """Do ``edit`` as one step of the window's undo stack; False if nothing changed."""
        return edit is not None and self.document.push(edit)

    def position_of(self, code: str) -> np.ndarray | None:
        """The landmark ``code`` as drawn: placed, else the first guess (scan frame, mm)."""
        lm = self.landmarks.placed.get(code)
        if lm is not None and lm.is_defined:
            return np.asarray(lm.position, float)
        if self.view is not None and code in self.view.guess:
            return np.asarray(self.view.guess[code], float)
        return None

    def set_placing(self, on: bool) -> None:
        """Clicks and drags go to the scan (the skull's picker rests meanwhile)."""
        if self.picker is not None:
            self.picker.enabled = bool(on)
        if self.skull_picker is not None:
            self.skull_picker.enabled = not on

    def on_pick(self, point: np.ndarray) -> None:
        """A click on the scan: place the selected code there, then select the next free one."""
        code = self.panel.selected_code()
        if not code:
            self.host.status("Choose a landmark code in the Fit scan list, then click the scan.")
            return
        if self._push(self.landmarks.place(code, point)):
            self.panel.select_next_unplaced(code, self.landmarks.placed)
            self.host.status(f"Placed {code} on the scan (Ctrl+Z undoes it).")

    def place(self, code: str, point: np.ndarray) -> bool:
        """Place (or move) ``code`` at ``point`` (scan frame, mm); one undo step."""
        return self._push(self.landmarks.place(code, point))

    def grab_target(self) -> tuple[str, np.ndarray] | None:
        code = self.panel.selected_code()
        if not code:
            return None
        p = self.position_of(code)
        return None if p is None else (code, p)

    def on_drag(self, code: str, point: np.ndarray) -> None:
        self._drag = (code, np.asarray(point, float))
        if not self._drag_scheduled:
            self._drag_scheduled = True
            QTimer.singleShot(0, self._draw_drag)

    def _draw_drag(self) -> None:
        self._drag_scheduled = False
        if self._drag is not None:
            self.draw_landmarks({self._drag[0]: self._drag[1]})

    def on_drag_end(self, code: str, point: np.ndarray | None) -> None:
        self._drag = None
        if point is None or not self._push(self.landmarks.place(code, point, "Drag")):
            self.draw_landmarks()

    def cancel_drag(self) -> None:
        if self.picker is not None and self.picker.dragging is not None:
            self.picker.finish_drag(cancel=True)

    def accept_selected(self) -> None:
        code = self.panel.selected_code()
        if not code or self.view is None or code not in self.view.guess:
            self.host.status("Select a landmark of the first guess to accept it.")
            return
        self._push(self.landmarks.place(code, self.view.guess[code], "Accept"))

    def accept_all(self) -> None:
        """Accept every guess over the scan not placed yet (one undo step)."""
        view = self.view
        if view is None:
            self.host.status("Fit the scan first: its landmarks are the first guess.")
            return
        todo = {
            c: p
            for c, p in view.guess.items()
            if c not in view.over_holes and c not in self.landmarks.placed
        }
        if self._push(self.landmarks.place_many(todo, f"Accept {len(todo)} guessed landmarks")):
            self.host.status(f"Accepted {len(todo)} landmarks of the first guess.")

    def remove_selected(self) -> None:
        code = self.panel.selected_code()
        if code:
            self._push(self.landmarks.remove(code))

    def undo(self) -> None:
        """The dock's Undo: the window's one undo stack (as Edit ▸ Undo)."""
        self.document.undo()

    def redo(self) -> None:
        self.document.redo()

    # ------------------------------------------------------------ drawing
    def _scan_actor(self) -> Any:
        actors = self._actors.get("scan")
        return actors[0] if actors else None

    def _clear(self, layer: str) -> None:
        if layer == "skin":
            self._on_scan_skin = None
        for actor in self._actors.pop(layer, []):
            self.plotter.remove_actor(actor, render=False)
        self.scene.request_render()

    def set_active(self, on: bool) -> None:
        """The dock came to the front (its scan, fitted skin and landmarks shown, the case's
        layers set aside) or was left (all of its drawing hidden, the case's layers back)."""
        self.active = bool(on)
        self._aside.set_aside(self.active and self.scan is not None)
        for layer, actors in self._actors.items():
            for actor in actors:
                actor.SetVisibility(self.active and self.panel.layer_visible(layer))
        if self._on_scan_skin is not None:
            self._on_scan_skin.SetVisibility(
                self.active and self.panel.layer_visible("skin") and not self._scan_shown()
            )
        self._show_scan_key()
        self.scene.request_render()

    def _add(self, layer: str, actor: Any) -> None:
        self._actors.setdefault(layer, []).append(actor)
        actor.SetVisibility(self.active and self.panel.layer_visible(layer))
        if layer == "skin":
            actor.GetProperty().SetOpacity(self.panel.skin_opacity())

    def actors(self, layer: str) -> list[Any]:
        """The drawn actors of ``"scan"``, ``"skin"`` or ``"landmarks"`` (tests)."""
        return list(self._actors.get(layer, []))

    def set_visible(self, layer: str, on: bool) -> None:
        for actor in self._actors.get(layer, []):
            actor.SetVisibility(bool(on) and self.active)
        if layer == "scan":  # the scan's colour key goes with the scan
            self._show_scan_key()
        if self._on_scan_skin is not None:  # the fitted skin on the scan: instead of the scan
            self._on_scan_skin.SetVisibility(
                self.active and self.panel.layer_visible("skin") and not self._scan_shown()
            )
        self.scene.request_render()

    def _set_opacity(self, layer: str, value: float) -> None:
        for actor in self._actors.get(layer, []):
            actor.GetProperty().SetOpacity(float(value))
        self.scene.request_render()

    def draw_scan(self) -> None:
        self._clear("scan")
        self._scan_poly = None
        if self.scan is None:
            return
        view = self.view
        own = self.scan.colours if self.panel.scan_colours() == "own" else None
        actor, self._scan_poly = face.add_scan(
            self.plotter,
            self.scan.mesh,
            None if view is None else view.distance,
            title=DISTANCE_TITLE,
            clim=DISTANCE_RANGE_MM,
            colours=own,
        )
        self._add("scan", actor)
        self._show_scan_key()
        self.scene.request_render()

    def draw_skin(self) -> None:
        self._clear("skin")
        if self.view is None:
            return
        parts, colours = self.view.skin_parts, self.view.skin_colours
        if self.panel.detail_shown() and self.view.detail_parts is not None:
            parts, colours = self.view.detail_parts, self.view.detail_colours
        # the scan's colours carried onto the skin: one per skin vertex, which both parts share
        rgb = None if colours is None else colours.rgb
        for i, part in enumerate(parts):
            if not part.n_faces:
                continue
            # translucent over the scan (back faces culled, no sorting); the camera is kept
            actor = face.add_skin_part(
                self.plotter, part, name=f"scan_fit_skin_{'on' if i else 'off'}_scan", rgb=rgb
            )
            self._add("skin", actor)
            if i:  # the part on the scan: only while the scan is hidden
                self._on_scan_skin = actor
                actor.SetVisibility(
                    self.active and self.panel.layer_visible("skin") and not self._scan_shown()
                )
        self.scene.request_render()

    def _show_scan_key(self) -> None:
        set_bar_visible(
            self.plotter,
            DISTANCE_TITLE,
            self.active
            and self.panel.layer_visible("scan")
            and self.panel.scan_colours() == "distance",
        )

    def _scan_shown(self) -> bool:
        return self.panel.layer_visible("scan") and self.scan is not None

    def landmark_states(self) -> dict[str, str]:
        """``{code: "placed" | "guess" | "over hole"}`` of every drawn landmark."""
        out: dict[str, str] = {}
        view = self.view
        if view is not None:
            for code in view.guess:
                out[code] = "over hole" if code in view.over_holes else "guess"
        for lm in self.landmarks.placed.defined():
            out[lm.code] = "placed"
        return out

    def draw_landmarks(self, override: dict[str, np.ndarray] | None = None) -> None:
        """Placed (green), first guess (orange; violet over holes), the selected one yellow."""
        self._clear("landmarks")
        override = override or {}
        states = self.landmark_states()
        points, statuses = [], []
        for code, state in states.items():
            p = override.get(code, self.position_of(code))
            if p is not None:
                points.append(p)
                statuses.append(state)
        drawn = []
        if points:
            drawn += markers.add_status_markers(
                self.plotter,
                np.array(points, float),
                statuses,
                STATE_COLOURS,
                MARKER_PX,
                "scan_fit_landmarks_",
            )
        code = self.panel.selected_code()
        p = override.get(code) if code else None
        if p is None and code:
            p = self.position_of(code)
        if code and p is not None:
            drawn.append(
                markers.add_selected(self.plotter, p, MARKER_PX, "scan_fit_landmarks_selected")
            )
            if not override:
                name = self.scan.names.get(code, "") if self.scan is not None else ""
                text = f"{code}: {name} ({states.get(code, 'not placed')})"
                drawn.append(markers.add_label(self.plotter, p, text, "scan_fit_landmarks_label"))
        for actor in drawn:
            self._add("landmarks", actor)
        self.scene.request_render()

    def reset_camera(self) -> None:
        """Look at the fitted face from the front; before a fit, at the whole scan."""
        renderer = self.plotter.renderer
        view = self.view
        if view is None:
            if self.scan is not None:
                lo, hi = self.scan.mesh.vertices.min(axis=0), self.scan.mesh.vertices.max(axis=0)
                renderer.ResetCamera(*np.column_stack([lo, hi]).ravel())
                renderer.ResetCameraClippingRange()
            self.scene.request_render()
            return
        b = view.face_bounds
        centre = np.array([(b[0] + b[1]) / 2, (b[2] + b[3]) / 2, (b[4] + b[5]) / 2])
        camera = renderer.GetActiveCamera()
        camera.SetFocalPoint(*centre)
        camera.SetPosition(*(centre + 600.0 * view.anterior))
        camera.SetViewUp(*view.superior)
        renderer.ResetCamera(*b)  # keeps the direction, fits the face
        camera.Zoom(1.15)
        renderer.ResetCameraClippingRange()
        self.scene.request_render()

    def detach(self) -> None:
        """Remove the picker's observers (before the view closes)."""
        if self.picker is not None:
            self.picker.detach()
            self.picker = None
        self.gui_call.close()
