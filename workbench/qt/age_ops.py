"""The "Age progression" tool of the window: a head shown at another age, live under a slider.

The method is the service's (:func:`workbench.services.age.change.age_head`,
``workbench age``); this tool runs it in the window's worker and shows the
results.  Export runs :func:`workbench.services.age.job.age_to_folder`, the
function the command line calls, with the same ``extra`` hook for
``report.pdf`` (the command line's writer, handed to this module by
``workbench gui`` through :func:`set_pdf_hook`: the window's layer may not
import the command line's).  The export runs in the worker, but the hook
draws the report's pictures with VTK, and worker threads never touch VTK
(ARCHITECTURE.md §3.4): the worker hands the hook to the GUI thread
(:class:`GuiCall`) and waits for it, so the folder is still written as one
piece by ``age_to_folder``.

Live preview
------------
One age step takes ~1-2 s, so the slider does not wait for it.  The tool
keeps a cache of results for whole-year target ages (per source head and
settings).  When the slider moves it draws at once the **nearest computed
age** (no blending: every head drawn is a real result of the service, and the
dock and the view's caption say which age it is), and the worker computes
the slider's age, then the whole years around it (±:attr:`AgeTool.prefetch_years`),
one job at a time, the one closest to the slider first.  The aged skin
(same vertices and triangles as the source) is moved in place, so following
the slider costs one points update, not a new actor.

Before / after
--------------
"Side by side": the source head to the left of the aged one (shifted by its
width + :data:`GAP_MM` along −x; the view looks at the faces from the
front).  "Overlay": both in place, the source translucent, the aged skin
coloured by each vertex's **displacement** from its source position (mm;
the two skins share vertices, so this is the vertex-to-vertex distance, not
a closest-surface distance).

Frames and units: mm, each head in its own Frankfort frame (x to the
subject's left, x = 0 midsagittal, y up, z toward the face); the aged heads
are settled in theirs, which shares axes and origin (between the porions)
with the source.  Not the case's skull frame; the tool's actors are its own,
not :data:`workbench.qt.scene.LAYERS`.

The case
--------
The case keeps the dock's *settings*, not its heads: "Keep in case" pushes
:class:`~workbench.commands.age_study.SetAgeStudy` with the dock's
:class:`~workbench.model.age_study.AgeStudy` (source, sex, ages, norms) on
the window's one undo stack, so Edit ▸ Undo takes it back and it is in the
audit log and the saved file.  When a case with a study is opened, or the
study changes by undo/redo, the dock shows its settings again (and ages the
head anew).  The case has no part holding a head (a reconstructed face is a
derived result of the window's session), so there is no "Apply": the heads
stay view only; Export… writes the aged head as a template pack (which
reconstructs, animates and ages again) with its report.

:func:`load_source`, :func:`age_step` and :func:`export_ages` are the
worker side (plain data, no Qt, no VTK); :class:`AgeTool` is the GUI side.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from PySide6.QtCore import QObject, Signal

from workbench.core.errors import InputError, WorkbenchError
from workbench.core.mesh import Mesh
from workbench.model.template import TemplateHead
from workbench.qt import relay
from workbench.qt.panels.age_panel import SOURCES as PANEL_SOURCES

if TYPE_CHECKING:
    from PySide6.QtWidgets import QWidget

    from workbench.model.age_study import AgeStudy
    from workbench.qt.document import Document
    from workbench.qt.panels.age_panel import AgePanel
    from workbench.qt.scene import SceneView
    from workbench.qt.workers import TaskRunner
    from workbench.services.age.change import AgeResult

#: worker channels: source loading, age steps (one at a time), export
LOAD_CHANNEL = "age_source"
CHANNEL = "age"
EXPORT_CHANNEL = "age_export"
#: space between the two heads side by side (mm)
GAP_MM = 40.0
#: opacity of the source skin in the overlay
OVERLAY_OPACITY = 0.25
DISTANCE_TITLE = "displacement mm"
#: fraction of an age step done when the service reports a step (by its first word)
STEP_FRACTIONS = {"measuring": 0.05, "solving": 0.3, "warping": 0.45}
BEFORE_COLOUR = (0.80, 0.80, 0.84)

ExtraHook = Callable[[Path, TemplateHead, list["AgeResult"]], list[Path]]
_PDF_HOOK: ExtraHook | None = None


def set_pdf_hook(hook: ExtraHook | None) -> None:
    """The ``extra`` writer :func:`export_ages` hands to ``age_to_folder`` (``report.pdf``).

    ``workbench gui`` sets the command line's own writer here, so the
    window's export writes what ``workbench age`` writes; without it (a
    window built by a script or a test) the export has no PDF.
    """
    global _PDF_HOOK
    _PDF_HOOK = hook


def pdf_hook() -> ExtraHook | None:
    return _PDF_HOOK


class GuiCall:
    """Lets a worker run a function on the GUI thread and wait for its result.

    Made on the GUI thread; :meth:`wrap` gives the worker a stand-in for
    ``fn`` that posts the call through :mod:`workbench.qt.relay` (plain data:
    the function, its arguments, a box and an event) and waits, checking
    ``report`` (which raises :class:`~workbench.core.errors.Cancelled` when
    the job is cancelled or the window shuts down) while it waits.
    """

    def __init__(self) -> None:
        self._key = relay.register(self._run)
        self.runs = 0

    def _run(self, payload: Any) -> None:
        fn, args, box, done = payload
        try:
            box.append((True, fn(*args)))
        except BaseException as exc:  # noqa: BLE001 - handed back to the waiting worker
            box.append((False, exc))
        finally:
            self.runs += 1
            done.set()

    def wrap(
        self, fn: Callable[..., Any], report: Callable[[str, float], None] | None, step: str
    ) -> Callable[..., Any]:
        key = self._key

        def on_gui_thread(*args: Any) -> Any:
            box: list[tuple[bool, Any]] = []
            done = threading.Event()
            relay.post(key, (fn, args, box, done))
            while not done.wait(0.1):
                if report is not None:
                    report(step, 0.96)
            ok, value = box[0]
            if not ok:
                raise value
            return value

        return on_gui_thread

    def close(self) -> None:
        relay.unregister(self._key)


class AgeHost(Protocol):
    """What the tool uses of the window: status line, readable errors, dialogs' parent."""

    messages: list[str]
    interactive: bool

    def status(self, text: str) -> None: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...

    def window(self) -> QWidget: ...


# ------------------------------------------------------------------ worker side (plain data)
@dataclass(frozen=True)
class AgeSettings:
    """What an age step depends on besides the head and the target age (ages in years)."""

    sex: str
    from_age: float
    ethnicity: str | None = None
    norms: str = "facial_norms"
    arc_increase: float = 0.0


@dataclass(frozen=True)
class NormsInfo:
    """The norms table's populations and the ages it covers: ``{(sex, ethnicity): (lo, hi)}``."""

    norms: str
    ethnicities: tuple[str, ...]
    ranges: dict[tuple[str, str], tuple[float, float]]


@dataclass(frozen=True)
class SourceHead:
    """A source head (head frame, mm) and the norms it will be aged with."""

    key: str
    head: TemplateHead
    norms: NormsInfo


@dataclass(frozen=True)
class AgeStep:
    """One computed target age: the service's result plus what drawing needs.

    ``normals`` are the aged skin's vertex normals; ``distance`` each skin
    vertex's displacement from the source (mm).
    """

    age: int
    result: AgeResult
    normals: np.ndarray
    distance: np.ndarray


def norms_info(norms: str = "facial_norms") -> NormsInfo:
    """Worker: the populations of ``norms`` and the ages each (sex, population) covers."""
    from workbench.io.growth_norms import load_growth_norms

    table = load_growth_norms(norms)
    ranges: dict[tuple[str, str], tuple[float, float]] = {}
    for eth in table.ethnicities():
        for sex in ("female", "male"):
            spans = [
                table.age_range(m.measurement_id, sex, eth)
                for m in table.measurements
                if table.has(m.measurement_id, sex, eth)
            ]
            if spans:
                ranges[(sex, eth)] = (min(a for a, _ in spans), max(b for _, b in spans))
    return NormsInfo(table.norms_id, tuple(table.ethnicities()), ranges)


def load_source(key: str, head: TemplateHead | None = None) -> SourceHead:
    """Worker: the source head (``reference:male|female``, or ``head`` as given) and its norms.

    The head is put in the Frankfort frame of its skull landmarks, where the
    service measures and ages it (a reconstruction is stored in the skull
    file's frame; a reference head already is in it), so the source drawn and
    the displacements are in the aged heads' frame.
    """
    from workbench.services.age.change import in_frankfort_frame
    from workbench.services.templates.cache import reference_head

    if head is None:
        kind, _, sex = key.partition(":")
        if kind != "reference" or sex not in ("female", "male"):
            raise InputError("age progression", f"no head '{key}' to age")
        head = reference_head(sex)
    head, _moved = in_frankfort_frame(head)
    return SourceHead(key, head, norms_info())


def age_step(
    head: TemplateHead,
    settings: AgeSettings,
    age: int,
    report: Callable[[str, float], None] | None = None,
) -> AgeStep:
    """Worker: ``head`` aged from ``settings.from_age`` to ``age`` years (the service's result)."""
    from workbench.core.normals import vertex_normals
    from workbench.services.age.change import age_head

    def say(message: str) -> None:
        if report is not None:
            words = message.split()
            report(message, STEP_FRACTIONS.get(words[0] if words else "", 0.0))

    result = age_head(
        head,
        sex=settings.sex,
        from_age=settings.from_age,
        to_age=float(age),
        norms=settings.norms,
        ethnicity=settings.ethnicity,
        arc_increase=settings.arc_increase,
        progress=say,
    )
    skin = result.head.skin
    distance = np.linalg.norm(skin.vertices - head.skin.vertices, axis=1)
    return AgeStep(int(age), result, vertex_normals(skin), distance)


def export_ages(
    head: TemplateHead,
    settings: AgeSettings,
    ages: Sequence[float],
    out: str | Path,
    *,
    force: bool = False,
    extra: ExtraHook | None = None,
    report: Callable[[str, float], None] | None = None,
    gui: GuiCall | None = None,
) -> tuple[list[AgeResult], list[Path]]:
    """Worker: :func:`~workbench.services.age.job.age_to_folder` with the tool's inputs.

    With ``gui``, ``extra`` (which may draw with VTK) runs on the GUI thread.
    """
    from workbench.services.age.job import age_to_folder

    if extra is not None and gui is not None:
        extra = gui.wrap(extra, report, "writing report.pdf (pictures on the GUI thread)")

    n = max(len(ages), 1)
    done = [0]

    def say(message: str) -> None:
        if message.startswith("age "):
            done[0] += 1
        if report is not None:
            report(message, min(0.95, (done[0] - 1) / n if done[0] else 0.0))

    return age_to_folder(
        head,
        out,
        sex=settings.sex,
        from_age=settings.from_age,
        ages=list(ages),
        norms=settings.norms,
        ethnicity=settings.ethnicity,
        arc_increase=settings.arc_increase,
        inputs=[
            {"role": "head", "template_id": head.template_id, "content_hash": head.content_hash}
        ],
        force=force,
        progress=say,
        extra=extra,
    )


# ------------------------------------------------------------------ GUI side
class AgeTool(QObject):
    """The "Age progression" tool: see the module docstring.

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
        self.files: list[Path] = []
        self._loading = ""
        self._generation = 0
        self._actors: dict[str, Any] = {}
        self._caption: Any = None
        self.gui_call = GuiCall()
        self._hidden_layers: list[str] = []
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

    @property
    def step(self) -> AgeStep | None:
        """The computed age drawn now."""
        return None if self.shown_age is None else self.cache.get(self.shown_age)

    def set_active(self, on: bool) -> None:
        """The dock was shown (load, draw) or hidden (the heads are hidden with it).

        While it is in front the case's layers (skull, landmarks, face ...: the
        specimen's frame, not the heads') are hidden, and shown again after.
        """
        self.active = bool(on)
        self._hide_case_layers(self.active)
        for actor in self._actors.values():
            actor.SetVisibility(self.active and self._wanted(actor))
        if self._caption is not None:
            self._caption.SetVisibility(self.active)
        self.scene.request_render()
        if on:
            self.ensure_loaded()

    def _hide_case_layers(self, hide: bool) -> None:
        scene = self.scene
        if hide:
            for layer, visible in scene.visible.items():
                if visible and scene.has(layer):
                    scene.set_visible(layer, False)
                    self._hidden_layers.append(layer)
            return
        for layer in self._hidden_layers:  # unless the user showed or hid it meanwhile
            if not scene.visible.get(layer, True):
                scene.set_visible(layer, True)
        self._hidden_layers.clear()

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
        if available and self.panel.source_key() == "fit" and self.source is not None:
            self.load("fit")

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
            panel.sex.setCurrentText(sex if kind == "reference" else self.case_sex())
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
        what = (
            "the case's reconstructed head"
            if source.key == "fit"
            else f"the reference {source.key.partition(':')[2]} head"
        )
        self.host.status(
            f"Age progression: {what} ({n:,} skin vertices; the heads are view only, Keep in "
            "case records the settings; the case's layers are hidden while this dock is in "
            "front)."
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

    # ------------------------------------------------------------ drawing
    def _mode_changed(self, _mode: str) -> None:
        self.draw()
        self.reset_camera()

    def actors(self) -> dict[str, Any]:
        """``{"before" | "after": actor}`` drawn by this tool (tests)."""
        return dict(self._actors)

    def offset(self) -> np.ndarray:
        """Where the source head is drawn relative to its frame (mm): side by side, to −x."""
        if self.source is None or self.panel.mode() != "side":
            return np.zeros(3)
        span = float(np.ptp(self.source.head.skin.vertices[:, 0]))
        return np.array([-(span + GAP_MM), 0.0, 0.0])

    def clear(self) -> None:
        for actor in self._actors.values():
            self.plotter.remove_actor(actor, render=False)
        self._actors.clear()
        if self._caption is not None:
            self.plotter.remove_actor(self._caption, render=False)
            self._caption = None
        self.scene.request_render()

    def draw(self) -> None:
        """(Re)draw the source head and the shown aged head for the panel's mode."""
        from workbench.qt.scene import SKIN, SMOOTH
        from workbench.render.snapshots import to_polydata

        self.clear()
        source = self.source
        if source is None or self.scene.closed:
            return
        overlay = self.panel.mode() == "overlay"
        skin = source.head.skin
        before = to_polydata(skin.transformed(_shift(self.offset())), normals=True)
        actor = self.plotter.add_mesh(
            before,
            color=BEFORE_COLOUR if overlay else SKIN,
            **SMOOTH,
            opacity=OVERLAY_OPACITY if overlay else 1.0,
            pickable=False,
            render=False,
            name="age_before",
        )
        if overlay:  # a translucent shell over the aged head: no depth sorting needed
            actor.GetProperty().BackfaceCullingOn()
        self._actors["before"] = actor
        self._caption = self.plotter.add_text(
            "", position="upper_left", font_size=11, color="black", name="age_caption"
        )
        self._draw_after(rebuild=True)

    def _draw_after(self, rebuild: bool = False) -> None:
        """The aged skin of :attr:`step`: built once, then its points moved in place."""
        from workbench.qt.scene import SCALAR_BAR, SKIN, SMOOTH
        from workbench.render.snapshots import to_polydata

        source, step = self.source, self.step
        if source is None or "before" not in self._actors or self.scene.closed:
            return
        overlay = self.panel.mode() == "overlay"
        actor = self._actors.get("after")
        if rebuild or actor is None:
            if actor is not None:
                self.plotter.remove_actor(actor, render=False)
            # a copy: VTK may share the array, and its points are moved in place below
            skin = source.head.skin
            poly = to_polydata(Mesh(skin.vertices.copy(), skin.faces.copy()), normals=True)
            kw: dict[str, Any] = {"color": SKIN}
            if overlay:
                poly.point_data[DISTANCE_TITLE] = np.zeros(poly.n_points)
                kw = {
                    "scalars": DISTANCE_TITLE,
                    "cmap": "viridis",
                    "clim": (0.0, 10.0),
                    "scalar_bar_args": dict(
                        SCALAR_BAR, title=DISTANCE_TITLE, n_labels=6, fmt="%.0f"
                    ),
                }
            actor = self.plotter.add_mesh(
                poly, **SMOOTH, pickable=False, render=False, name="age_after", **kw
            )
            self._actors["after"] = actor
        if step is not None:
            data = drawn_data(actor)
            _set_array(data.GetPoints().GetData(), step.result.head.skin.vertices)
            data.GetPoints().Modified()
            normals = data.GetPointData().GetNormals()
            if normals is not None:
                _set_array(normals, step.normals)
            if overlay:
                scalars = data.GetPointData().GetArray(DISTANCE_TITLE)
                if scalars is not None:
                    _set_array(scalars, step.distance)
                hi = max(1.0, 5.0 * math.ceil(float(np.percentile(step.distance, 99)) / 5.0))
                actor.GetMapper().SetScalarRange(0.0, hi)
                lut = actor.GetMapper().GetLookupTable()
                if lut is not None:
                    lut.SetRange(0.0, hi)
            data.Modified()
        actor.SetVisibility(self.active and step is not None)
        self._update_caption()
        self.scene.request_render()

    def _update_caption(self) -> None:
        if self._caption is None:
            return
        s = self.settings()
        shown = "–" if self.shown_age is None else f"{self.shown_age} y"
        if self.panel.mode() == "side":
            text = f"left: {s.from_age:g} y (source)   right: {shown} (aged)"
        else:
            text = f"{shown} (coloured: displacement from {s.from_age:g} y, mm); source translucent"
        self._caption.SetText(2, text)  # a corner annotation: 2 = upper left
        self._caption.SetVisibility(self.active)

    def drawn_points(self, which: str) -> np.ndarray:
        """The drawn skin points of ``"before"`` or ``"after"`` (mm; tests)."""
        from vtkmodules.util.numpy_support import vtk_to_numpy

        actor = self._actors[which]
        return vtk_to_numpy(drawn_data(actor).GetPoints().GetData()).copy()

    def reset_camera(self) -> None:
        """Look at both heads from the front (+z toward the face, +y up)."""
        source = self.source
        if source is None or self.scene.closed:
            return
        v = source.head.skin.vertices
        lo = np.minimum(v.min(axis=0), v.min(axis=0) + self.offset())
        hi = np.maximum(v.max(axis=0), v.max(axis=0) + self.offset())
        centre = (lo + hi) / 2
        renderer = self.plotter.renderer
        camera = renderer.GetActiveCamera()
        camera.SetFocalPoint(*centre)
        camera.SetPosition(*(centre + np.array([0.0, 0.0, 800.0])))
        camera.SetViewUp(0.0, 1.0, 0.0)
        renderer.ResetCamera(*np.column_stack([lo, hi]).ravel())
        camera.Zoom(1.3 if self.panel.mode() == "side" else 1.05)
        renderer.ResetCameraClippingRange()
        self.scene.request_render()

    # ------------------------------------------------------------ export
    def ages_to_export(self) -> list[int]:
        if self.panel.export_all.isChecked() and self.cache:
            return sorted(self.cache)
        return [self.target]

    def ask_export(self) -> None:
        from PySide6.QtWidgets import QFileDialog

        if self.source is None:
            self.host.status("Open the Age progression dock first (the head loads there).")
            return
        name, _ = QFileDialog.getSaveFileName(
            self.host.window(), "Export the aged head (a new folder)", f"aged_{self.target}y", ""
        )
        if name:
            self.export_to(name)

    def _may_replace(self, folder: Path) -> bool:
        if not self.host.interactive:
            return False
        from PySide6.QtWidgets import QMessageBox

        answer = QMessageBox.question(
            self.host.window(),
            "Replace the folder?",
            f"{folder} already exists and is not empty.\n\nReplace it? (The old folder is "
            "kept beside it as a numbered copy.)",
            QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.Cancel,
            QMessageBox.StandardButton.Cancel,
        )
        return answer == QMessageBox.StandardButton.Yes

    def export_to(self, folder: str | Path, force: bool = False) -> bool:
        """Write the aged head(s) into ``folder`` (worker) as ``workbench age`` does.

        The ages: the target, or every computed one (the panel's check box).
        False when refused at once (no head, or a non-empty folder not to be replaced).
        """
        from workbench.qt.scan_fit_ops import folder_is_free

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
        head, settings, ages, extra = source.head, self.settings(), self.ages_to_export(), _PDF_HOOK
        gui = self.gui_call
        self.panel.export_button.setEnabled(False)
        self.panel.show_status(f"Exporting {', '.join(f'{a} y' for a in ages)} to {out.name} …")
        self.runner.submit(
            EXPORT_CHANNEL,
            f"Exporting the aged head to {out.name} …",
            lambda report: export_ages(
                head, settings, ages, out, force=force, extra=extra, report=report, gui=gui
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


#: the service's option names (its command line's) as the dock's fields
FIELDS = {
    "--from": "Age now",
    "--to": "Target age",
    "--sex": "Sex",
    "--ethnicity": "Norms of",
    "--norms": "Norms",
    "--arc-increase": "Arc increase",
}


def in_dock(exc: BaseException) -> BaseException:
    """An :class:`InputError` naming a command-line option renamed after the dock's field."""
    if isinstance(exc, InputError) and exc.source in FIELDS:
        hint = exc.hint
        if hint and "--norms" in hint:  # the dock has no norms import: keep the first advice
            hint = hint.split(", or ")[0]
        return InputError(FIELDS[exc.source], exc.problem, hint)
    return exc


def study_text(study: AgeStudy) -> str:
    """One line describing a study: head, sex, ages (years), population."""
    head = (
        "reconstructed head"
        if study.source == "reconstruction"
        else study.source.replace("reference:", "reference ")
    )
    ages = ", ".join(f"{a:g}" for a in study.target_ages)
    text = f"{head}, {study.sex}, {study.from_age:g} y → {ages} y"
    if study.ethnicity:
        text += f", norms of {study.ethnicity}"
    if study.arc_increase:
        text += f", arc increase {study.arc_increase * 100:g} %"
    return text


def figures_html(result: AgeResult) -> str:
    """The result's main figures (mm) as a small HTML table."""
    f = result.figures
    hc = f.get("head_circumference_mm", {}) or {}
    res = f.get("hard_residual_mm", {}) or {}
    normed = [r for r in result.rows if r.constraint == "norms"]
    high = sum(1 for r in normed if abs(r.z_after) > 2 or abs(r.z_before) > 2)
    rows = [
        (
            "Head circumference",
            f"{hc.get('before')} → {hc.get('after')} mm (target {hc.get('target')})",
        ),
        (
            "  z-score",
            f"{_z_html(hc.get('z_before'))} → {_z_html(hc.get('z_after'))} ({hc.get('chart', '')})",
        ),
        ("Global scale", f"{f.get('global_scale')}"),
        (
            "Hard constraints",
            f"{f.get('hard_constraints')}: residual median {res.get('median')} mm, "
            f"max {res.get('max')} mm",
        ),
        ("Largest z change", f"{f.get('z_change_max')}"),
        ("|z| > 2", f"{high} of {len(normed)} measurements with norms"),
        ("Fold-overs", f"{f.get('fold_overs')}"),
    ]
    body = "".join(f"<tr><td>{k}</td><td>&nbsp;<b>{v}</b></td></tr>" for k, v in rows)
    notes = "".join(f"<br><i>note: {w}</i>" for w in result.warnings)
    unconstrained = f.get("unconstrained") or []
    if unconstrained:
        notes += f"<br><i>unconstrained (landmark missing): {', '.join(unconstrained)}</i>"
    return f"<table>{body}</table>{notes}"


def drawn_data(actor: Any) -> Any:
    """The polydata an actor of ``plotter.add_mesh`` draws (mm): pyvista's mapper dataset.

    Not ``GetMapper().GetInput()``: with scalars the mapper is fed through a
    pipeline connection, and its input is an empty output until the first render.
    """
    return actor.mapper.dataset


def _z_html(z: Any) -> str:
    """A z-score, marked (as in the table) when it is beyond ±2."""
    from workbench.qt.panels.age_panel import HIGHLIGHT, out_of_range

    if not isinstance(z, (int, float)):
        return "–"
    if out_of_range(float(z)):
        return f"<span style='background-color:{HIGHLIGHT.name()}'>{z}</span>"
    return f"{z}"


def _shift(offset: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = offset
    return m


def _set_array(vtk_array: Any, values: np.ndarray) -> None:
    from vtkmodules.util.numpy_support import vtk_to_numpy

    target = vtk_to_numpy(vtk_array)
    target[:] = np.asarray(values, float).reshape(target.shape)
    vtk_array.Modified()
