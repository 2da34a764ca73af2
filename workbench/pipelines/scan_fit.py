"""Scan → fitted head pack, as a finished folder: the pack, its pictures and ``fit_report.pdf``.

:func:`fit_scan_to_folder` is ``workbench fit-scan`` and the window's *Save
fitted scan pack…*: :func:`workbench.services.scan_fit.pack.fit_scan_pack`
(the fit, the template pack, ``fit_report.json``) with the report's pictures
and PDF written into the same staged folder.  Frames and units: the pack is
in the scan file's frame, mm (``template.json`` says so).
"""

from __future__ import annotations

from collections.abc import Callable
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

from workbench.pipelines.outcome import Say, quiet

if TYPE_CHECKING:
    from workbench.core.landmarks import LandmarkSet
    from workbench.services.scan_fit.settings import ScanFit

#: writes the pictures and the PDF into the staged pack: ``draw(folder, fit, scan_name, note)``;
#: the window wraps it to run on its GUI thread
Draw = Callable[[Path, "ScanFit", str, Say], list[Path]]


def fit_scan_to_folder(
    scan_path: str | PathLike[str],
    out: str | PathLike[str],
    *,
    landmarks: str | PathLike[str] | LandmarkSet | None = None,
    report: bool = True,
    draw: Draw | None = None,
    note: Say = quiet,
    **settings: Any,
) -> tuple[ScanFit, list[Path]]:
    """Fit the reference head to the scan and write the pack with its report into ``out``.

    ``settings`` are :func:`~workbench.services.scan_fit.pack.fit_scan_pack`'s
    (units, scale, sex, table, build, orientation, bone_path, texture, force,
    progress, detail).  ``landmarks``: a landmark file, or the landmarks
    placed in the window (scan frame, mm).  ``report=False``: no pictures
    and no PDF.  ``note`` hears why a picture is missing.
    """
    from workbench.services.scan_fit.pack import fit_scan_pack

    name = Path(scan_path).name
    writer = draw or write_scan_fit_report

    def extra(folder: Path, fit: ScanFit) -> list[Path]:
        return writer(folder, fit, name, note)

    return fit_scan_pack(
        scan_path, out, landmarks=landmarks, extra=extra if report else None, **settings
    )


def write_scan_fit_report(
    folder: Path, result: ScanFit, scan_name: str, note: Say = quiet
) -> list[Path]:
    """``pictures/*.png`` and ``fit_report.pdf`` into the staged pack; without OpenGL, no maps."""
    from workbench import __version__
    from workbench.reporting.fit_scan_report import fit_scan_summary, write_fit_scan_pdf

    try:
        from workbench.render.scan_fit_pictures import render_scan_fit_pictures

        pictures, notes = render_scan_fit_pictures(result, folder / "pictures")
    except (ImportError, RuntimeError, OSError) as exc:  # no pyvista / OpenGL at all
        pictures, notes = {}, [f"no pictures ({exc})"]
    for message in notes:
        note(message)
    notes = [*notes, *(f"Data credit: {c}" for c in result.figures.get("credits", []))]
    pdf = write_fit_scan_pdf(
        fit_scan_summary(result, scan_name),
        folder / "fit_report.pdf",
        pictures,
        notes=notes,
        software=f"workbench {__version__}",
    )
    return [*pictures.values(), pdf]
