"""The age tool's worker side: plain data in, plain data out (no Qt widgets, no VTK).

:func:`load_source` reads a head and the norms it is aged with, :func:`age_step`
ages it to one target age, :func:`export_ages` writes the folder ``workbench age``
writes.  They run in the window's worker thread.  The one exception to "no VTK" is
the PDF report's hook, which draws pictures: :class:`GuiCall` hands it to the GUI
thread while the worker waits.  The hook itself is set by ``workbench gui`` through
:func:`set_pdf_hook` (the window's layer may not import the command line's).

Units mm, ages in years; heads in their own head frame.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.errors import InputError
from workbench.model.template import TemplateHead
from workbench.qt import relay

if TYPE_CHECKING:
    from workbench.services.age.change import AgeResult

#: fraction of an age step done when the service reports a step (by its first word)
STEP_FRACTIONS = {"measuring": 0.05, "solving": 0.3, "warping": 0.45}

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
