"""The "Age progression" tool's controller: the dock's choices, the worker's jobs, the case.

See :mod:`workbench.qt.tools.age` for what the tool shows and why; the worker side
is :mod:`~workbench.qt.tools.age.work`, the drawing :mod:`~workbench.qt.tools.age.drawing`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from PySide6.QtCore import QObject, Signal

from workbench.core.errors import InputError, WorkbenchError
from workbench.model.template import TemplateHead
from workbench.qt.gui_call import GuiCall
from workbench.qt.panels.age_panel import SOURCES as PANEL_SOURCES
from workbench.qt.tools.age.drawing import AgeDrawing
from workbench.qt.tools.age.text import figures_html, in_dock, study_text
from workbench.qt.tools.age.work import (
    AgeSettings,
    NormsInfo,
    SourceHead,
    age_step,
    export_ages,
    load_source,
)
from workbench.qt.tools.common import CaseLayersAside, folder_is_free
from workbench.render.visuals.heads import DISTANCE_TITLE
from workbench.render.visuals.scalar_bars import set_bar_visible

if TYPE_CHECKING:
    from PySide6.QtWidgets import QWidget

    from workbench.model.age_study import AgeStudy
    from workbench.qt.document import Document
    from workbench.qt.panels.age_panel import AgePanel
    from workbench.qt.scene import SceneView
    from workbench.qt.tools.age.work import AgeStep
    from workbench.qt.workers import TaskRunner
    from workbench.services.age.change import AgeResult

#: worker channels: source loading, age steps (one at a time), export
LOAD_CHANNEL = "age_source"
CHANNEL = "age"
EXPORT_CHANNEL = "age_export"


class AgeHost(Protocol):
    """What the tool uses of the window: status line, readable errors, dialogs' parent."""

    messages: list[str]
    interactive: bool

    def status(self, text: str) -> None: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...

    def window(self) -> QWidget: ...


class AgeTool(QObject, AgeDrawing):
    """The "Age progression" tool: see :mod:`workbench.qt.tools.age`.

    Parameters
    ----------
    fitted_head : callable
        The case's reconstructed head (head frame, mm) or None.
    case_sex : callable
        The case's sex (its dowel settings), used with the reconstructed head.
    document : Document, optional
        The window's open case (default: ``host.document`` if the host has
        one): "Keep in case" pushes the age study on its stack, and the dock
        follows the study it keeps.  Without one the dock is view only.

    Signals
    -------
    loaded()        a source head is loaded
    shown(int)      a computed age was drawn (its target age, years)
    exported(list)  the files of an export
    """

    loaded = Signal()
    shown = Signal(int)
    exported = Signal(list)

    def __init__(
        self,
        panel: AgePanel,
        scene: SceneView,
        plotter: Any,
        runner: TaskRunner,
        host: AgeHost,
        *,
        fitted_head: Callable[[], TemplateHead | None] = lambda: None,
        case_sex: Callable[[], str] = lambda: "male",
        document: Document | None = None,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.panel, self.scene, self.plotter = panel, scene, plotter
        self.runner, self.host = runner, host
        self.fitted_head, self.case_sex = fitted_head, case_sex
        #: the head fitted to a scan in the Fit scan dock (:meth:`scan_changed`), or None
        self.scan_head: TemplateHead | None = None
        self.source: SourceHead | None = None
        self.norms: NormsInfo | None = None
        #: computed ages of the current source and settings, and the ages that failed
        self.cache: dict[int, AgeStep] = {}
        self.failed: dict[int, str] = {}
        #: the age drawn now (None: no aged head shown)
        self.shown_age: int | None = None
        #: the age asked for (the slider's, or one given to :meth:`request`)
        self.target = panel.target_age()
        #: whole years computed around the target once it is done
        self.prefetch_years = 2
        self.active = False
        #: the heads were drawn while the dock was behind another: set the camera when shown
        self.camera_pending = False
        self.files: list[Path] = []
        self._loading = ""
        self._generation = 0
        self._actors: dict[str, Any] = {}
        self._caption: Any = None
        self.gui_call = GuiCall()
        self._aside = CaseLayersAside(scene)
        panel.source_changed.connect(self.load)
        panel.settings_changed.connect(self._settings_changed)
        panel.target_changed.connect(self.request)
        panel.mode_changed.connect(self._mode_changed)
        panel.export_requested.connect(self.ask_export)
        runner.progress_changed.connect(self._on_progress)
        #: norms table of the settings (the dock has no field for it: a kept study's is
        #: used as it is); the arc increase is the dock's field
        self.norms_id = "facial_norms"
        #: a study being shown whose sex, population and target apply when the head loads
        self._pending: AgeStudy | None = None
        self.document = document if document is not None else getattr(host, "document", None)
        panel.keep_requested.connect(self.keep)
        if self.document is not None:
            self.document.case_replaced.connect(self._case_replaced)
            self.document.part_changed.connect(self._part_changed)
            self._case_replaced()

    # ------------------------------------------------------------ state
    def settings(self) -> AgeSettings:
        p = self.panel
        return AgeSettings(
            p.sex_value(),
            p.from_age_value(),
            p.ethnicity_value(),
            self.norms_id,
            p.arc_increase_value(),
        )

    def set_active(self, on: bool) -> None:
        """The dock was shown (load, draw) or hidden (the heads are hidden with it).

        While it is in front the case's layers (skull, landmarks, face ...: the
        specimen's frame, not the heads') are hidden, and shown again after.
        """
        self.active = bool(on)
        self._aside.set_aside(self.active)
        for actor in self._actors.values():
            actor.SetVisibility(self.active and self._wanted(actor))
        if self._caption is not None:
            self._caption.SetVisibility(self.active)
        # the displacement colour bar goes and comes with the aged skin it belongs to
        after = self._actors.get("after")
        shown = self.active and after is not None and self._wanted(after)
        set_bar_visible(self.plotter, DISTANCE_TITLE, shown)
        self.scene.request_render()
        if on:
            self.ensure_loaded()
            if self.camera_pending:  # heads drawn while the dock was behind another
                self.reset_camera()

    def _wanted(self, actor: Any) -> bool:
        return actor is not self._actors.get("after") or self.step is not None

    # ------------------------------------------------------------ loading
    def ensure_loaded(self) -> None:
        if self.source is None and not self._loading:
            self.load(self.panel.source_key())

    def load(self, key: str) -> None:
        """Load the source head ``key`` (worker); the computed ages go with the old one."""
        if key == self._loading:
            return
        head = None
        if key == "fit":
            head = self.fitted_head()
            if head is None:
                self.panel.show_error("Reconstruct the face first: no reconstructed head to age.")
                return
        elif key == "scan":
            head = self.scan_head
            if head is None:
                self.panel.show_error("Fit a scan first (Fit scan dock): no fitted scan to age.")
                return
        self._loading = key
        self.panel.show_status("Loading the head …")
        self.runner.submit(
            LOAD_CHANNEL,
            "Loading the head to age …",
            lambda: load_source(key, head),
            self._loaded,
            self._load_failed,
        )

    def fit_changed(self, available: bool) -> None:
        """The case's reconstruction changed: offer it, and age the new one if it is the source."""
        self.panel.set_fit_available(available)  # withdrawn: the panel falls back to a reference
        pending = self._pending
        if available and pending is not None and pending.source == "reconstruction":
            # a reopened case's study of its reconstruction: the head to age exists now
            self.show_study(pending)
            return
        if available and self.panel.source_key() == "fit" and self.source is not None:
            self.load("fit")

    def scan_changed(self, head: TemplateHead | None) -> None:
        """The head fitted to a scan (Fit scan dock) changed: offer it, and age the new one
        if it is the source (head frame or the scan's frame: it is put in its Frankfort
        frame when loaded, as a reconstruction is)."""
        self.scan_head = head
        self.panel.set_source_available("scan", head is not None)
        if head is not None and self.panel.source_key() == "scan" and self.source is not None:
            self.load("scan")

    def _load_failed(self, exc: BaseException) -> None:
        self._loading = ""
        self.panel.show_status("The head could not be loaded.")
        self.host.show_error("Could not load the head to age", exc)

    def _loaded(self, source: SourceHead) -> None:
        if source.key != self._loading or self.scene.closed:
            return
        self._loading = ""
        self.source, self.norms = source, source.norms
        panel = self.panel
        blocked = [w.blockSignals(True) for w in (panel.sex, panel.ethnicity)]
        try:
            kind, _, sex = source.key.partition(":")
            own = self.case_sex() if source.key == "fit" else source.head.sex  # a scan: its fit's
            panel.sex.setCurrentText(sex if kind == "reference" else own)
            if panel.ethnicity.count() == 0:
                panel.ethnicity.addItems(list(source.norms.ethnicities))
                if "European" in source.norms.ethnicities:
                    panel.ethnicity.setCurrentText("European")
            pending, self._pending = self._pending, None
            if pending is not None:  # a kept study: its sex and population, not the head's
                panel.sex.setCurrentText(pending.sex)
                if pending.ethnicity is not None:
                    panel.ethnicity.setCurrentText(pending.ethnicity)
        finally:
            for w, b in zip((panel.sex, panel.ethnicity), blocked, strict=True):
                w.blockSignals(b)
        self._reset_results()
        if pending is not None:
            self._set_slider(round(pending.target_ages[0]))
        self.draw()
        self.reset_camera()
        self.loaded.emit()
        n = source.head.skin.n_vertices
        what = {"fit": "the case's reconstructed head", "scan": "the head fitted to the scan"}.get(
            source.key, f"the reference {source.key.partition(':')[2]} head"
        )
        if self.active:  # (a reopened case's study loads behind another dock: no word then)
            self.host.status(
                f"Age progression: {what} ({n:,} skin vertices; the heads are view only, Keep "
                "in case records the settings; the case's layers are hidden while this dock "
                "is in front)."
            )
        self.request(self.panel.target_age())

    def _settings_changed(self) -> None:
        if self.source is None:
            return
        self._reset_results()
        self.draw()
        self.request(self.target)

    def _reset_results(self) -> None:
        """Forget computed ages (new source or settings) and stop the running step."""
        self._generation += 1
        self.runner.cancel(CHANNEL)
        self.cache.clear()
        self.failed.clear()
        self.shown_age = None
        self.panel.show_error("")
        self.panel.show_rows(())
        self.panel.show_figures("")
        if self.norms is not None:
            s = self.settings()
            lo, hi = self.norms.ranges.get((s.sex, s.ethnicity or ""), (0.0, 40.0))
            slider = self.panel.target
            blocked = slider.blockSignals(True)
            try:
                self.panel.set_age_range(lo, hi)
            finally:
                slider.blockSignals(blocked)
            self.panel.target_value.setText(f"{slider.value()} y")

    # ------------------------------------------------------------ the case's age study
    def case_open(self) -> bool:
        """A case is open (a skull or a case file), so "Keep in case" has a case to keep it in."""
        doc = self.document
        return doc is not None and (doc.path is not None or doc.has_specimen)

    def current_study(self) -> AgeStudy:
        """The dock's settings as an :class:`~workbench.model.age_study.AgeStudy` (years).

        The target ages: the slider's first, then (with "every computed age")
        the other computed ones.  Raises ``AgeStudyError`` for a bad value.
        """
        from workbench.model.age_study import AgeStudy

        p, s = self.panel, self.settings()
        key = p.source_key()
        ages = [float(p.target_age())]
        if p.export_all.isChecked():
            ages += [float(a) for a in sorted(self.cache) if a != p.target_age()]
        return AgeStudy(
            source="reconstruction" if key == "fit" else key,
            sex=s.sex,
            from_age=s.from_age,
            target_ages=tuple(ages),
            norms=s.norms,
            ethnicity=s.ethnicity,
            arc_increase=s.arc_increase,
        )

    def keep(self) -> bool:
        """ "Keep in case": push the dock's settings as the case's study (one undo step)."""
        from workbench.commands.age_study import SetAgeStudy
        from workbench.model.age_study import AgeStudyError

        doc = self.document
        if doc is None or not self.case_open():
            self.host.status("Open a case first: the age study is kept in a case.")
            return False
        if self.panel.source_key() == "scan":
            self.panel.show_error(
                "Not kept: the fitted scan is not part of the case (save it with Save pack… in "
                "the Fit scan dock); a kept study ages a reference head or the reconstruction."
            )
            return False
        try:
            study = self.current_study()
        except AgeStudyError as exc:
            self.panel.show_error(f"Not kept: {exc}")
            return False
        if doc.case.age_study == study:
            self.host.status("The case already keeps these age-study settings.")
            return False
        if not doc.push(SetAgeStudy(study)):
            return False
        text = f"Age study kept in the case (undo: Ctrl+Z): {study_text(study)}."
        self.panel.show_case_note(text)
        self.host.status(text)
        return True

    def _case_replaced(self) -> None:
        open_ = self.case_open()
        self.panel.set_keep_enabled(open_, "Open a skull or a case first.")
        self.norms_id = "facial_norms"
        self.panel.set_arc_increase(0.0)
        study = self.document.case.age_study if self.document is not None else None
        if study is None:
            self.panel.show_case_note("" if not open_ else "The case keeps no age study.")
            return
        self.show_study(study)
        self.panel.show_case_note(f"The case keeps an age study: {study_text(study)}.")

    def _part_changed(self, part: str) -> None:
        if part == "appearance":  # the hair chosen for the face: on both heads
            self._draw_hair()
            self.scene.request_render()
            return
        if part != "age_study" or self.document is None:
            return
        study = self.document.case.age_study
        if study is None:
            self.panel.show_case_note("The case keeps no age study (undone).")
            return
        if study != self._study_or_none():
            self.show_study(study)
        self.panel.show_case_note(
            f"Age study kept in the case (undo: Ctrl+Z): {study_text(study)}."
        )

    def _study_or_none(self) -> AgeStudy | None:
        from workbench.model.age_study import AgeStudyError

        try:
            return self.current_study()
        except AgeStudyError:
            return None

    def show_study(self, study: AgeStudy) -> None:
        """Set the dock to ``study``'s settings and age the head with them.

        A reconstruction source needs the case's reconstructed face (the dock
        says so when there is none); the norms population and sex apply when
        the head loads if it is not loaded yet.
        """
        p = self.panel
        before = self.settings() if self.source is not None else None
        key = "fit" if study.source == "reconstruction" else study.source
        title = next(t for t, k in PANEL_SOURCES.items() if k == key)
        widgets = (p.source, p.sex, p.from_age, p.ethnicity, p.target, p.export_all)
        blocked = [w.blockSignals(True) for w in widgets]
        try:
            p.source.setCurrentText(title)
            p.sex.setCurrentText(study.sex)
            p.from_age.setValue(study.from_age)
            if study.ethnicity is not None and p.ethnicity.findText(study.ethnicity) >= 0:
                p.ethnicity.setCurrentText(study.ethnicity)
            p.export_all.setChecked(len(study.target_ages) > 1)
            self.norms_id = study.norms
            p.set_arc_increase(study.arc_increase)
        finally:
            for w, b in zip(widgets, blocked, strict=True):
                w.blockSignals(b)
        target = round(study.target_ages[0])
        self._set_slider(target)
        if self.source is None or self.source.key != key:
            self._pending = study
            if self._loading == key:
                return  # the head is loading: the study applies when it is there
            if self.source is not None or self.active or self._loading:
                self._loading = ""  # a different head: load it even if another is loading
                self.load(key)
            return
        if self.settings() != before:
            self._reset_results()
            self.draw()
        self.request(target)

    def _set_slider(self, age: int) -> None:
        slider = self.panel.target
        blocked = slider.blockSignals(True)
        try:
            slider.setValue(age)
        finally:
            slider.blockSignals(blocked)
        self.target = int(slider.value())
        self.panel.target_value.setText(f"{slider.value()} y")

    # ------------------------------------------------------------ the slider
    def request(self, age: float) -> None:
        """Show ``age`` (years; whole years): the nearest computed age now, ``age`` when done."""
        self.target = int(round(float(age)))
        if self.source is None:
            self.ensure_loaded()
            return
        self.show()
        self._schedule()

    def _next_age(self) -> int | None:
        """The next age to compute: the target, then whole years around it, nearest first."""
        lo, hi = self.panel.target.minimum(), self.panel.target.maximum()
        order = [self.target]
        for k in range(1, self.prefetch_years + 1):
            order += [a for a in (self.target + k, self.target - k) if lo <= a <= hi]
        for age in order:
            if age not in self.cache and age not in self.failed:
                return age
        return None

    def _schedule(self) -> None:
        source = self.source
        if source is None or self.runner.is_running(CHANNEL):
            return
        age = self._next_age()
        if age is None:
            return
        head, settings, generation = source.head, self.settings(), self._generation
        self.runner.submit(
            CHANNEL,
            f"Ageing the head to {age} y …",
            lambda report: age_step(head, settings, age, report),
            lambda step: self._computed(generation, step),
            lambda exc: self._step_failed(generation, age, exc),
            progress=True,
        )
        if age == self.target and self.shown_age != age:
            self.panel.show_status(self._status_text(computing=age))

    def _computed(self, generation: int, step: AgeStep) -> None:
        if generation != self._generation or self.scene.closed:
            return
        self.cache[step.age] = step
        self.show()
        self._schedule()

    def _step_failed(self, generation: int, age: int, exc: BaseException) -> None:
        if generation != self._generation:
            return
        from workbench.qt import dialogs

        self.failed[age] = dialogs.error_text(f"Could not age the head to {age} y", in_dock(exc))[0]
        if not isinstance(exc, WorkbenchError):  # a bug: the details go to the error dialog
            self.host.show_error(f"Could not age the head to {age} y", exc)
        self.show()
        self._schedule()

    def _on_progress(self, channel: str, step: str, fraction: float) -> None:
        if channel == EXPORT_CHANNEL:
            self.panel.show_status(f"Export: {step} ({fraction * 100:.0f} %)")

    # ------------------------------------------------------------ showing
    def nearest_computed(self, age: int) -> int | None:
        if not self.cache:
            return None
        return min(self.cache, key=lambda a: (abs(a - age), a))

    def show(self) -> None:
        """Draw the computed age nearest the target; the table and figures follow."""
        target = self.target
        if target in self.failed:
            self.panel.show_error(self.failed[target])
            self.shown_age = None
            self.panel.show_rows(())
            self.panel.show_figures("")
            self._draw_after()
            self.panel.show_status(f"No head at {target} y (see the message below).")
            return
        self.panel.show_error("")
        age = self.nearest_computed(target)
        if age != self.shown_age:
            self.shown_age = age
            step = self.step
            self.panel.show_rows(step.result.rows if step is not None else ())
            self.panel.show_figures(figures_html(step.result) if step is not None else "")
            self._draw_after()
            if age is not None:
                self.shown.emit(age)
        computing = target if target not in self.cache else None
        self.panel.show_status(self._status_text(computing=computing))

    def _status_text(self, computing: int | None = None) -> str:
        s = self.settings()
        age = self.shown_age
        parts = [f"From {s.from_age:g} y ({s.sex})."]
        if self.source is not None:
            from workbench.services.age.job import sex_mismatch

            # the command line refuses this without --allow-sex-mismatch; the dock, where the
            # sex is chosen on purpose, says it beside the results
            mismatch = sex_mismatch(self.source.head, s.sex)
            if mismatch:
                parts.append(f"Warning: {mismatch}.")
        if age is None:
            parts.append("No aged head yet.")
        else:
            step = self.cache[age]
            parts.append(
                f"Showing {age} y (computed in {step.result.figures.get('seconds', 0):.1f} s)."
            )
        if computing is not None and age != computing:
            parts.append(f"Computing {computing} y …")
        return " ".join(parts)

    # ------------------------------------------------------------ export
    def ages_to_export(self) -> list[int]:
        if self.panel.export_all.isChecked() and self.cache:
            return sorted(self.cache)
        return [self.target]

    def ask_export(self) -> None:
        """Ask for the export folder (a new name is fine), starting in the case's folder."""
        from workbench.qt import dialogs

        if self.source is None:
            self.host.status("Open the Age progression dock first (the head loads there).")
            return

        case_path = None if self.document is None else self.document.path
        suggested = dialogs.start_folder(case_path) / f"aged_{self.target}y"
        name = dialogs.ask_new_folder(
            self.host.window(), "Export the aged head (a new folder)", suggested
        )
        if name:
            self.export_to(name)

    def _may_replace(self, folder: Path) -> bool:
        from workbench.qt import dialogs

        return self.host.interactive and dialogs.ask_replace_folder(
            self.host.window(), folder, "the aged heads"
        )

    def export_to(self, folder: str | Path, force: bool = False) -> bool:
        """Write the aged head(s) into ``folder`` (worker) as ``workbench age`` does.

        The ages: the target, or every computed one (the panel's check box).
        False when refused at once (no head, or a non-empty folder not to be replaced).
        """
        source = self.source
        if source is None:
            self.host.status("Load a head first (Age progression dock).")
            return False
        out = Path(folder)
        if not force and not folder_is_free(out):
            if not self._may_replace(out):
                exc = InputError(
                    out,
                    "already exists and is not empty; refusing to replace it",
                    "choose a new folder name, or confirm replacing it",
                )
                self.panel.show_error(f"Not exported: {exc}")
                return False
            force = True
        head, settings, ages = source.head, self.settings(), self.ages_to_export()
        gui = self.gui_call
        self.panel.export_button.setEnabled(False)
        self.panel.show_status(f"Exporting {', '.join(f'{a} y' for a in ages)} to {out.name} …")
        self.runner.submit(
            EXPORT_CHANNEL,
            f"Exporting the aged head to {out.name} …",
            lambda report: export_ages(
                head, settings, ages, out, force=force, report=report, gui=gui
            ),
            self._exported,
            self._export_failed,
            progress=True,
        )
        return True

    def _exported(self, result: tuple[list[AgeResult], list[Path]]) -> None:
        _results, files = result
        self.panel.export_button.setEnabled(True)
        self.files = list(files)
        folder = files[0].parent if files else None
        self.panel.show_status(f"Exported {len(files)} files to {folder}.")
        self.host.status(f"Aged head exported: {folder} ({len(files)} files)")
        self.exported.emit(self.files)

    def _export_failed(self, exc: BaseException) -> None:
        from workbench.qt import dialogs

        self.panel.export_button.setEnabled(True)
        self.panel.show_status("Not exported.")
        self.panel.show_error(dialogs.error_text("Not exported", exc)[0])
        if not isinstance(exc, WorkbenchError):
            self.host.show_error("Could not export the aged head", exc)

    def detach(self) -> None:
        """Stop computing (before the view closes)."""
        self.runner.cancel(CHANNEL)
        self.gui_call.close()
