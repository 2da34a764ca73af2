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
    from workbench.core.colour_transfer import ScanColours, SkinColours
    from workbench.services.scan_fit.settings import PreparedScan, ScanFit

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

    The colours the file carries (PLY / OBJ vertex colours, an OBJ texture
    through its material's ``map_Kd``) are read too (:func:`read_colours`); a
    problem with them leaves the scan without colours and says why
    (``OpenedScan.colour_note``), it never stops the scan from opening.
    """
    from workbench.core.units import check_units_choice, resolve_units
    from workbench.io.catalogue import load_catalogue
    from workbench.io.meshes import read_mesh
    from workbench.services.scan_fit.checks import prepare_scan
    from workbench.services.templates.cache import reference_head

    check_units_choice(units, scale)
    path = Path(path)
    read = read_mesh(path, units=units if scale is None else "auto", scale=scale, kind="face")
    if scale is None and units == "auto":
        resolve_units(read.units, "auto", source=str(path))
    # the checks of check_scan_mesh, the working scan kept (to carry the colours onto it)
    prepared = prepare_scan(read.mesh, path)
    _ = read.mesh.vertex_normals  # cached: spares the GUI thread when drawing
    codes = reference_head("male").skin_landmarks.codes
    catalogue = load_catalogue()
    names = {}
    for code in codes:
        entry = catalogue.get(code, "skin")
        names[code] = entry.name if entry is not None else ""
    colours, working, note = read_colours(path, read.mesh, prepared)
    return OpenedScan(
        path,
        units,
        scale,
        read.mesh,
        float(read.scale_applied),
        tuple(codes),
        names,
        read.messages,
        colours=colours,
        working_colours=working,
        colour_note=note,
        vertex_of=prepared.vertex_of,
    )


def _problem(exc: BaseException) -> str:
    """A colour problem in a few words: the file's name and what is wrong."""
    from workbench.core.errors import InputError

    if isinstance(exc, InputError):
        return f"{Path(exc.source).name}: {exc.problem}"
    return f"{type(exc).__name__}: {exc}"


def read_colours(
    path: Path, mesh: Mesh, prepared: PreparedScan
) -> tuple[ScanColours | None, ScanColours | None, str]:
    """Worker: ``(file colours, colours on the working scan, note)`` of the scan file.

    ``mesh`` is the file's mesh (:func:`~workbench.io.meshes.read_mesh`) and
    ``prepared`` its working scan.  No colours: ``(None, None, "")``.  Any
    problem (an unreadable or missing texture image, colours that do not match
    the mesh) gives ``(None, None, why)``: the scan is shown and fitted without
    its colours.
    """
    from workbench.io.scan_colours import colours_on_working_scan, read_scan_colours

    try:
        colours = read_scan_colours(path)
        if colours is None:
            return None, None, ""
        if colours.n_vertices != mesh.n_vertices or len(colours.faces) != mesh.n_faces:
            return (
                None,
                None,
                (
                    f"its colours belong to {colours.n_vertices:,} vertices and "
                    f"{len(colours.faces):,} triangles, the mesh has {mesh.n_vertices:,} and "
                    f"{mesh.n_faces:,}"
                ),
            )
        working = colours_on_working_scan(
            colours, mesh.vertices, prepared.mesh, prepared.vertex_of, prepared.face_source
        )
    except Exception as exc:  # noqa: BLE001 - a colour problem must not stop the scan opening
        return None, None, _problem(exc)
    return colours, working, ""


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


def skin_colours(
    fit: ScanFit, working: ScanColours | None
) -> tuple[SkinColours | None, SkinColours | None, str]:
    """Worker: the scan's colours carried onto the fitted skin and onto its detailed skin
    (head frame, as the pack does: :func:`~workbench.core.colour_transfer.transfer_colours`
    from the fit's working scan, observed within 3 mm, filled elsewhere), and a note.

    ``(None, None, "")`` when the scan has no colours; ``(None, None, why)`` when
    they could not be carried over (the fit is shown all the same).
    """
    from workbench.core.colour_transfer import transfer_colours
    from workbench.core.spatial import MeshIndex

    if working is None or fit.scan is None:
        return None, None, ""
    try:
        index = MeshIndex.shared(fit.scan)  # the pack's index of the same scan
        skin = transfer_colours(fit.head.skin, fit.scan, working, index=index)
        detail = None
        if fit.detail is not None:
            fine = fit.detail.apply(fit.head.skin.vertices)
            detail = transfer_colours(fine, fit.scan, working, index=index)
    except Exception as exc:  # noqa: BLE001 - the fit is shown without its colours
        return (
            None,
            None,
            f"the scan's colours could not be carried onto the skin ({_problem(exc)})",
        )
    return skin, detail, ""


def fit_view(
    fit: ScanFit,
    scan: Mesh,
    seeds: int = 0,
    *,
    vertex_of: np.ndarray | None = None,
    colours: ScanColours | None = None,
) -> FitView:
    """Worker: map a fit into the scan's frame for drawing (see :class:`FitView`).

    ``vertex_of`` (:attr:`OpenedScan.vertex_of`) puts the fit's distances (per
    working scan vertex) onto the vertices of the file's mesh ``scan``;
    ``colours`` (:attr:`OpenedScan.working_colours`) are carried onto the
    fitted skin (:func:`skin_colours`).
    """
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
    distance = on_file_vertices(fit.scan_distance, scan.n_vertices, vertex_of)
    skin_rgb, detail_rgb, note = skin_colours(fit, colours)
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
        skin_rgb,
        detail_rgb,
        note,
    )


def on_file_vertices(
    distance: np.ndarray | None, n_file: int, vertex_of: np.ndarray | None
) -> np.ndarray:
    """The fit's per working-scan-vertex ``distance`` on the file's ``n_file`` vertices
    (NaN: not counted, or left out of the working scan); as it is when the two have
    the same vertices, or no map is known."""
    if distance is None:
        return np.full(n_file, np.nan)
    d = np.asarray(distance, float)
    if vertex_of is None or len(vertex_of) != n_file or int(vertex_of.max(initial=-1)) >= len(d):
        return d
    kept = vertex_of >= 0
    out = np.full(n_file, np.nan)
    out[kept] = d[vertex_of[kept]]
    return out


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
        step = "carrying the scan's colours onto" if scan.working_colours else "drawing"
        report(f"{step} the fit", 0.97)
    return fit_view(
        result,
        scan.mesh,
        0 if seeds is None else len(seeds),
        vertex_of=scan.vertex_of,
        colours=scan.working_colours,
    )


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
    view = fit_view(
        result,
        scan.mesh,
        0 if seeds is None else len(seeds),
        vertex_of=scan.vertex_of,
        colours=scan.working_colours,
    )
    return view, list(files)
