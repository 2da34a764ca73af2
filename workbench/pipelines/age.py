"""Head → aged heads, as a finished folder: the packs, ``sequence.glb``, pictures and ``report.pdf``.

:func:`age_to_folder_with_report` is ``workbench age`` and the window's age
*Export…*: :func:`workbench.services.age.job.age_to_folder` (the aged packs,
``report.json``, the morph sequence) with the report's pictures and PDF
(:func:`write_age_report_pdf`) written into the same staged folder.  Frames
and units: every head in its own Frankfort frame, mm.
"""

from __future__ import annotations

from collections.abc import Callable
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

from workbench.pipelines.outcome import Say

if TYPE_CHECKING:
    from workbench.model.template import TemplateHead
    from workbench.services.age.change import AgeResult

#: writes the pictures and the PDF into the staged folder: ``draw(folder, head, results)``;
#: the window wraps it to run on its GUI thread
Draw = Callable[[Path, "TemplateHead", list["AgeResult"]], list[Path]]


def age_to_folder_with_report(
    head: TemplateHead,
    out: str | PathLike[str],
    *,
    report: bool = True,
    draw: Draw | None = None,
    note: Say | None = None,
    **settings: Any,
) -> tuple[list[AgeResult], list[Path]]:
    """Age ``head`` and write the folder with its report (``report=False``: no pictures, no PDF).

    ``settings`` are :func:`~workbench.services.age.job.age_to_folder`'s (sex,
    from_age, ages, norms, ethnicity, arc_increase, inputs, input_paths,
    force, progress, warnings).  ``draw`` replaces :func:`write_age_report_pdf`
    (the window hands it to its GUI thread); ``note`` hears why a picture is missing.
    """
    from workbench.services.age.job import age_to_folder

    def default(folder: Path, aged_from: TemplateHead, results: list[AgeResult]) -> list[Path]:
        return write_age_report_pdf(folder, aged_from, results, note)

    writer = draw or default
    return age_to_folder(head, out, extra=writer if report else None, **settings)


def write_age_report_pdf(
    folder: Path, head: TemplateHead, results: list[AgeResult], note: Say | None = None
) -> list[Path]:
    """``pictures/*.png`` and ``report.pdf`` into the staged output folder; without OpenGL, no pictures.

    The norms' citations and the source head's data credits (a Visible Human
    sample named anywhere in its provenance) are looked up here, so the
    reporting layer needs neither ``workbench.io``'s registry nor the render layer.
    """
    from workbench import __version__
    from workbench.io.growth_norms import load_growth_norms, load_head_circumference
    from workbench.io.samples import registry
    from workbench.reporting.age_report import (
        chart_references,
        provenance_credits,
        source_keys,
        write_age_report,
    )
    from workbench.services.age.growth_tables import load_vault_norms

    try:
        from workbench.render.age_pictures import render_age_pictures

        pictures, notes = render_age_pictures(head, results, folder / "pictures")
    except (ImportError, RuntimeError, OSError) as exc:  # no pyvista / OpenGL at all
        pictures, notes = {}, [f"no pictures ({exc})"]
    for message in notes:
        if note is not None:
            note(message)
    change = dict(results[0].head.provenance.get("age_change") or {})
    table = load_growth_norms(str(change.get("norms") or results[0].figures["norms"]))
    vault = load_vault_norms()  # the vault's own table (issue 33): its keys are not the norms'
    citations = {
        key: cited if (cited := table.citation(key)) != key else vault.citation(key)
        for key in source_keys(results)
    }
    charts = load_head_circumference()
    citations |= {name: charts.citation(name) for name in chart_references(results)}
    credited: dict[str, str] = {}
    for sample in registry().values():
        if not sample.credit:
            continue
        for f in (*sample.files, *sample.extra_files):
            credited[f.sha256] = sample.credit
            credited[Path(f.path).name] = sample.credit
        credited[sample.name] = sample.credit
        if "visible human" in sample.description.lower():
            credited["visible human"] = sample.credit
    pdf = write_age_report(
        folder,
        head,
        results,
        pictures,
        notes=notes,
        software=f"workbench {__version__}",
        citations=citations,
        credits=provenance_credits(head.provenance or {}, credited),
    )
    return [*pictures.values(), pdf]
