"""The age tool's worker side: plain data in, plain data out (no Qt widgets, no VTK).

:func:`load_source` reads a head and the norms it is aged with, :func:`age_step`
ages it to one target age, :func:`export_ages` writes the folder ``workbench age``
writes.  They run in the window's worker thread.  The one exception to "no VTK" is
the report's pictures: :func:`export_ages` calls the age pipeline
(:func:`workbench.pipelines.age.age_to_folder_with_report`, what ``workbench age``
calls), and :class:`~workbench.qt.gui_call.GuiCall` hands its picture and PDF writer
to the GUI thread while the worker waits.

Units mm, ages in years; heads in their own head frame.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from workbench.core.errors import InputError
from workbench.model.template import TemplateHead
from workbench.qt.gui_call import GuiCall

if TYPE_CHECKING:
    from workbench.services.age.change import AgeResult

#: fraction of an age step done when the service reports a step (by its first word)
STEP_FRACTIONS = {"measuring": 0.05, "solving": 0.3, "warping": 0.45}


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
    pdf: bool = True,
    report: Callable[[str, float], None] | None = None,
    gui: GuiCall | None = None,
) -> tuple[list[AgeResult], list[Path]]:
    """Worker: the age pipeline (:func:`~workbench.pipelines.age.age_to_folder_with_report`,
    as ``workbench age``) with the tool's inputs: the aged packs, pictures and ``report.pdf``.

    With ``gui``, the pictures and the PDF (drawn with VTK) are written on the GUI thread.
    """
    from workbench.pipelines.age import age_to_folder_with_report, write_age_report_pdf

    draw = (
        None
        if gui is None
        else gui.wrap(
            write_age_report_pdf, report, "writing report.pdf (pictures on the GUI thread)"
        )
    )

    n = max(len(ages), 1)
    done = [0]

    def say(message: str) -> None:
        if message.startswith("age "):
            done[0] += 1
        if report is not None:
            report(message, min(0.95, (done[0] - 1) / n if done[0] else 0.0))

    return age_to_folder_with_report(
        head,
        out,
        report=pdf,
        draw=draw,
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
    )
