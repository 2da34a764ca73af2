"""The scan-fit tool's worker side: read a scan, fit it, write a pack (no Qt, no VTK).

These run in the window's worker thread and call the scan-fit service as
``workbench fit-scan`` does; :func:`fit_view` maps a fit into the scan's own frame
for drawing.  Units mm.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.qt.gui_call import GuiCall
from workbench.qt.tools.scan_fit.state import FitView, OpenedScan, ScanFitSettings

if TYPE_CHECKING:
    from workbench.services.scan_fit.settings import ScanFit

#: fraction of the fit done when the service reports a step (by the step's first word)
STEP_FRACTIONS = {
    "orienting": 0.03,
    "registering": 0.12,
    "placing": 0.7,
    "carrying": 0.75,
    "measuring": 0.95,
}
#: the placed landmarks in a saved pack (scan frame, mm)
PLACED_FILE = "landmarks_on_scan.mrk.json"


def read_scan(path: str | Path, units: str = "auto", scale: float | None = None) -> OpenedScan:
    """Worker: read and check a scan exactly as :func:`fit_scan_pack` does (mm).

    Raises :class:`~workbench.core.errors.UnitsError` when ``units`` is
    "auto" and the size does not look like mm (the window asks), and
    :class:`~workbench.core.errors.InputError` for a file that is not a
    face scan (a point cloud, a few triangles, a size not a head's).
    """
    from workbench.core.units import check_units_choice, resolve_units
    from workbench.io.catalogue import load_catalogue
    from workbench.io.meshes import read_mesh
    from workbench.services.scan_fit.checks import check_scan_mesh
    from workbench.services.templates.cache import reference_head

    check_units_choice(units, scale)
    path = Path(path)
    read = read_mesh(path, units=units if scale is None else "auto", scale=scale, kind="face")
    if scale is None and units == "auto":
        resolve_units(read.units, "auto", source=str(path))
    check_scan_mesh(read.mesh, path)
    _ = read.mesh.vertex_normals  # cached: spares the GUI thread when drawing
    codes = reference_head("male").skin_landmarks.codes
    catalogue = load_catalogue()
    names = {}
    for code in codes:
        entry = catalogue.get(code, "skin")
        names[code] = entry.name if entry is not None else ""
    return OpenedScan(
        path, units, scale, read.mesh, float(read.scale_applied), tuple(codes), names, read.messages
    )


def _fraction_reporter(report: Callable[[str, float], None] | None) -> Callable[[str], None]:
    """The service's step messages as ``report(step, fraction)`` (which may cancel)."""
    last = [0.0]

    def say(message: str) -> None:
        words = message.split()
        first = words[0] if words else ""
        last[0] = max(last[0], STEP_FRACTIONS.get(first, last[0]))
        if report is not None:
            report(message, last[0])

    return say


def fit_view(fit: ScanFit, scan: Mesh, seeds: int = 0) -> FitView:
    """Worker: map a fit into the scan's frame for drawing (see :class:`FitView`)."""
    from workbench.core.spatial import MeshIndex
    from workbench.services.templates.regions import face_regions

    back = np.linalg.inv(fit.input_to_head)
    skin = fit.head.skin.transformed(back)  # winding flipped when the scan was mirrored
    on = np.asarray(fit.skin_on_scan, bool)[skin.faces].all(axis=1)
    parts = (Mesh(skin.vertices, skin.faces[~on]), Mesh(skin.vertices, skin.faces[on]))
    for part in parts:
        part.__dict__["vertex_normals"] = skin.vertex_normals  # shading of the whole skin
    detail_parts = None
    if fit.detail is not None:
        fine = fit.detail.apply(fit.head.skin.vertices).transformed(back)
        fine_on = on[fit.detail.parent_faces]
        detail_parts = (
            Mesh(fine.vertices, fine.faces[~fine_on]),
            Mesh(fine.vertices, fine.faces[fine_on]),
        )
        for part in detail_parts:
            part.__dict__["vertex_normals"] = fine.vertex_normals
    lms = fit.head.skin_landmarks.defined()
    codes = list(lms.codes)
    guess_pts = fit.to_input(lms.positions_of(codes)) if codes else np.zeros((0, 3))
    guess = {c: p for c, p in zip(codes, guess_pts, strict=True)}
    absent = fit.figures.get("skin_landmark_to_scan_mm", {}).get("absent", [])
    to_scan = MeshIndex(scan).closest_points(guess_pts).distances if len(guess_pts) else np.zeros(0)
    ids = np.concatenate(list(face_regions(fit.head).values()))
    face = skin.vertices[np.unique(ids)] if len(ids) else skin.vertices
    lo, hi = face.min(axis=0), face.max(axis=0)
    a, s = back[:3, :3] @ [0.0, 0.0, 1.0], back[:3, :3] @ [0.0, 1.0, 0.0]
    distance = (
        np.asarray(fit.scan_distance, float)
        if fit.scan_distance is not None
        else np.full(scan.n_vertices, np.nan)
    )
    return FitView(
        fit,
        skin,
        parts,
        distance,
        guess,
        frozenset(absent),
        {c: float(d) for c, d in zip(codes, to_scan, strict=True)},
        a / np.linalg.norm(a),
        s / np.linalg.norm(s),
        np.column_stack([lo, hi]).ravel(),
        seeds,
        {c: float(lms[c].confidence) for c in codes},
        detail_parts,
    )


def run_scan_fit(
    scan: OpenedScan,
    placed: LandmarkSet | None,
    settings: ScanFitSettings,
    report: Callable[[str, float], None] | None = None,
) -> FitView:
    """Worker: :func:`fit_scan` on the opened scan, seeded by ``placed`` (scan frame, mm)."""
    from workbench.model.evidence import file_sha256
    from workbench.services.scan_fit.fit import fit_scan

    seeds = placed if placed is not None and len(placed) else None
    # the inputs as the pack records them (Save pack then writes this fit, not a new one)
    inputs: list[dict[str, Any]] = [
        {"role": "scan", "file": scan.path.name, "sha256": file_sha256(scan.path)}
    ]
    if seeds is not None:
        inputs.append(
            {"role": "skin_landmarks", "file": "(placed in the window)", "count": len(seeds)}
        )
    result = fit_scan(
        scan.mesh,
        landmarks=seeds,
        sex=settings.sex,
        table=settings.table,
        build=settings.build,
        source=str(scan.path),
        inputs=inputs,
        progress=_fraction_reporter(report),
    )
    if report is not None:
        report("drawing the fit", 0.98)
    return fit_view(result, scan.mesh, 0 if seeds is None else len(seeds))


def save_pack(
    scan: OpenedScan,
    out: str | Path,
    placed: LandmarkSet | None,
    settings: ScanFitSettings,
    *,
    force: bool = False,
    report: Callable[[str, float], None] | None = None,
    gui: GuiCall | None = None,
    fitted: ScanFit | None = None,
) -> tuple[FitView, list[Path]]:
    """Worker: the scan-fit pipeline (:func:`~workbench.pipelines.scan_fit.fit_scan_to_folder`,
    as ``workbench fit-scan``) with the tool's inputs; returns the fit and the files.

    The pack holds what the command line writes, ``fit_report.pdf`` and its
    pictures included (drawn on the GUI thread when ``gui`` is given).  The
    placed landmarks (scan frame, mm) go to the fit as they are and are
    copied into the pack as :data:`PLACED_FILE`.  ``fitted``: the fit shown, written as
    it is when it was made from the same scan, landmarks and settings (no second fit).
    """
    from workbench.io.markups import write_mrk_json
    from workbench.pipelines.scan_fit import fit_scan_to_folder, write_scan_fit_report

    seeds = placed if placed is not None and len(placed) else None
    pictures = (
        write_scan_fit_report
        if gui is None
        else gui.wrap(write_scan_fit_report, report, "writing fit_report.pdf (pictures)")
    )

    def draw(folder: Path, result: ScanFit, name: str, note: Callable[[str], None]) -> list[Path]:
        files = list(pictures(folder, result, name, note))
        if seeds is not None:
            write_mrk_json(folder / PLACED_FILE, seeds, "RAS")
            files.append(folder / PLACED_FILE)
        return files

    result, files = fit_scan_to_folder(
        scan.path,
        out,
        landmarks=seeds,
        draw=draw,
        units=scan.units,
        scale=scan.scale,
        sex=settings.sex,
        table=settings.table,
        build=settings.build,
        force=force,
        progress=_fraction_reporter(report),
        fitted=fitted,
    )
    return fit_view(result, scan.mesh, 0 if seeds is None else len(seeds)), list(files)
