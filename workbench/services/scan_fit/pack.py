"""The scan fit as a template pack: read the files, fit, write the pack and its report.

:func:`fit_scan_pack` reads a scan file (and its skin landmarks, a texture
image, a ``--bone`` surface: :func:`_read_scan`, :func:`_read_landmarks`,
:func:`_read_bone`), runs :func:`~workbench.services.scan_fit.fit.fit_scan`
and writes the pack as a whole (:func:`_write_pack`: the template,
``fit_report.json``, the detail layer, the scan's colour carried onto the
fitted skin).

Units: the files' numbers are converted to mm by ``units`` / ``scale`` (one
unit for scan, landmarks and bone); the scan, its landmarks and the bone
share the scan file's frame; the pack is in the fitted person's head frame
(``fit_report.json``'s ``input_to_head`` maps the file's frame into it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeGuard

import numpy as np

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.io.atomic import write_json_atomic
from workbench.services.scan_fit.checks import check_landmarks_on_scan, prepare_scan
from workbench.services.scan_fit.fit import fit_scan
from workbench.services.scan_fit.settings import (
    COLOUR_ATLAS_SIZE,
    PreparedScan,
    Progress,
    ScanFit,
)

if TYPE_CHECKING:
    from workbench.core.colour_transfer import ScanColours


@dataclass(frozen=True)
class _ScanFile:
    """A scan file read for the fit (:func:`_read_scan`; the file's frame, mm).

    Attributes
    ----------
    path : Path
        The scan file.
    prepared : PreparedScan
        Its mesh made ready to fit.
    colours : ScanColours, optional
        Its colours on the working scan.
    factor : float
        The scale applied to its numbers (to mm); the landmarks and the bone get the same.
    inputs : list of dict
        The input files' roles, names and SHA-256 (the scan, its texture; the landmark
        and bone files are appended as they are read).
    """

    path: Path
    prepared: PreparedScan
    colours: ScanColours | None
    factor: float
    inputs: list[dict]


def fit_scan_pack(
    scan_path: str | PathLike[str],
    out: str | PathLike[str],
    *,
    units: str = "auto",
    scale: float | None = None,
    landmarks: str | PathLike[str] | LandmarkSet | None = None,
    sex: str = "male",
    table: str = DEFAULT_DEPTH_TABLE,
    build: str | float = "normal",
    orientation: tuple | None = None,
    bone_path: str | PathLike[str] | None = None,
    texture: str | PathLike[str] | None = None,
    force: bool = False,
    progress: Progress | None = None,
    extra: Callable[[Path, ScanFit], list[Path]] | None = None,
    detail: bool = True,
    fitted: ScanFit | None = None,
) -> tuple[ScanFit, list[Path]]:
    """Read the scan (and landmarks, bone),
    :func:`~workbench.services.scan_fit.fit.fit_scan`, write the pack and
    ``fit_report.json`` to ``out``.

    The scan, its landmark file and the bone share one frame and one unit
    (``units`` or ``scale`` converts them to mm).  ``out`` is written as a
    whole (:func:`workbench.io.outputs.staged_folder`): an existing pack is
    replaced only with ``force`` and a failure leaves it as it was.
    Where the scan carries vertex colours or a UV texture (or ``texture``
    names the image its UVs refer to), the colour is carried onto the fitted
    skin (Lee, Terzopoulos & Waters 1993 did this with their scanner's
    reflectance image): ``skin_colour.ply`` (vertex colours) and
    ``skin_textured.obj`` + ``.mtl`` + ``skin_texture.png`` (an atlas) in
    the pack; skin away from the scan gets colour diffused from around.
    The scan's fine detail over the subdivided skin is written as
    ``skin_detailed.ply`` (the mesh) and ``skin_detail.npz`` (the layer, to
    re-detail an animated or aged skin: :mod:`workbench.io.skin_detail_export`),
    unless ``detail`` is False.
    ``extra(folder, result)`` writes further files into the staged pack (the
    CLI's PDF report, which needs the render layer) and returns their paths.
    ``fitted``: a fit of this scan made already (the window's, shown to the user),
    written as it is when it was made from the same inputs (scan bytes, landmarks),
    sex, table and build; otherwise the scan is fitted again.
    """
    from workbench.core.units import check_units_choice
    from workbench.io.outputs import check_output_folder, write_folder

    check_units_choice(units, scale)
    # landmarks placed in the window have no file
    landmark_file = None if isinstance(landmarks, LandmarkSet) else landmarks
    sources = [scan_path, landmark_file, bone_path, texture]
    check_output_folder(out, sources, force)  # before the fit, which takes a while
    scan = _read_scan(scan_path, units, scale, texture, progress)
    path, prepared, inputs = scan.path, scan.prepared, scan.inputs
    lms = None
    if landmarks is not None:
        lms = _read_landmarks(landmarks, scan, sex)
    bone = None
    if bone_path is not None:
        bone = _read_bone(bone_path, scan)
    if _same_fit(fitted, inputs, sex, table, build, bone, orientation, detail):
        result = fitted
    else:
        result = fit_scan(
            prepared.mesh,
            landmarks=lms,
            sex=sex,
            table=table,
            build=build,
            orientation=orientation,
            bone=bone,
            source=str(path),
            inputs=inputs,
            progress=progress,
            detail=detail,
            bone_source=str(bone_path),
        )
    # (fit_scan prepared the prepared mesh again, finding nothing to do: the file's story)
    notes = tuple(n for n in prepared.notes if n not in result.warnings)  # (a reused fit has them)
    result = replace(result, warnings=(*notes, *result.warnings))
    result.figures["scan_preparation"] = prepared.figures

    from workbench.io.samples import credits_for

    credits = credits_for([path, bone_path])
    if credits:  # a CT's skin from the Visible Human data carries NLM's credit line
        result.figures["credits"] = credits

    def write(folder: Path) -> list[Path]:
        return _write_pack(folder, result, scan.colours, path, progress, extra)

    return result, write_folder(out, write, force=force, inputs=sources)


def _same_fit(
    fitted: ScanFit | None,
    inputs: list[dict[str, Any]],
    sex: str,
    table: str,
    build: str | float,
    bone: Any,
    orientation: tuple | None,
    detail: bool,
) -> TypeGuard[ScanFit]:
    """Whether ``fitted`` was made from these inputs and settings (so it need not be redone)."""
    if fitted is None or bone is not None or orientation is not None:
        return False
    if detail and fitted.detail is None:
        return False
    made = fitted.head.provenance
    depth = made.get("depth_table") or {}
    return bool(
        list(made.get("built_from") or []) == [dict(i) for i in inputs]
        and depth.get("sex") == sex
        and depth.get("table") == table
        and depth.get("build") == str(build)
    )


def _read_scan(
    scan_path: str | PathLike[str],
    units: str,
    scale: float | None,
    texture: str | PathLike[str] | None,
    progress: Progress | None,
) -> _ScanFile:
    """The scan file read in ``units`` (or times ``scale``), prepared
    (:func:`~workbench.services.scan_fit.checks.prepare_scan`), its colours (vertex
    colours or a UV texture, ``texture`` naming its image) on the working scan; units
    ``"auto"`` judged on what is kept."""
    from workbench.core.units import detect_units, resolve_units
    from workbench.io.meshes import read_mesh
    from workbench.io.scan_colours import read_scan_colours
    from workbench.model.evidence import file_sha256

    path = Path(scan_path)
    read = read_mesh(path, units=units if scale is None else "auto", scale=scale, kind="face")
    prepared = prepare_scan(read.mesh, path, progress)
    colours = _working_colours(read_scan_colours(path, texture=texture), read.mesh, prepared)
    if scale is None and units == "auto":  # judged on what is kept (not a stray blob)
        resolve_units(detect_units(prepared.mesh, "face"), "auto", source=str(path))
    factor = read.scale_applied
    inputs = [{"role": "scan", "file": path.name, "sha256": file_sha256(path)}]
    if texture is not None:
        inputs.append(
            {"role": "texture", "file": Path(texture).name, "sha256": file_sha256(Path(texture))}
        )
    return _ScanFile(path, prepared, colours, factor, inputs)


def _read_landmarks(
    landmarks: str | PathLike[str] | LandmarkSet, scan: _ScanFile, sex: str
) -> LandmarkSet:
    """The skin landmark file, in the scan's units, checked against the scan
    (:func:`~workbench.services.scan_fit.checks.check_landmarks_on_scan`, the reference
    of ``sex`` telling which landmarks may coincide); noted in ``scan.inputs``.

    A :class:`LandmarkSet` (the window's placed landmarks) is already in the scan's
    frame and in mm; it is checked the same way and noted as placed, without a file.
    """
    from workbench.io.catalogue import load_catalogue
    from workbench.io.markups import read_landmarks
    from workbench.model.evidence import file_sha256
    from workbench.services.templates.cache import reference_head

    factor, inputs, prepared, path = scan.factor, scan.inputs, scan.prepared, scan.path
    known = reference_head(sex).skin_landmarks.as_dict()
    if isinstance(landmarks, LandmarkSet):
        inputs.append(
            {"role": "skin_landmarks", "file": "(placed in the window)", "count": len(landmarks)}
        )
        check_landmarks_on_scan(landmarks, prepared.mesh, "placed landmarks", path.name, known)
        return landmarks
    lms = read_landmarks(
        landmarks, "skin", catalogue=load_catalogue(), allow_undefined=True
    ).landmarks.transformed(np.diag([factor, factor, factor, 1.0]))
    inputs.append(
        {
            "role": "skin_landmarks",
            "file": Path(landmarks).name,
            "sha256": file_sha256(Path(landmarks)),
        }
    )
    check_landmarks_on_scan(lms, prepared.mesh, landmarks, path.name, known)
    return lms


def _read_bone(bone_path: str | PathLike[str], scan: _ScanFile) -> Mesh:
    """The ``--bone`` surface in the scan's units; refused when it is the scan file itself.
    Noted in ``scan.inputs``."""
    from workbench.io.meshes import read_mesh
    from workbench.model.evidence import file_sha256

    factor, inputs, path = scan.factor, scan.inputs, scan.path
    bone_sha = file_sha256(Path(bone_path))
    if bone_sha == inputs[0]["sha256"]:
        raise InputError(
            bone_path,
            f"(--bone) is the scan itself (the same content as {path.name}): the skin "
            "cannot be its own bone",
            "give the bone surface of the same CT (workbench mesh-from-ct CT --tissue "
            "bone), or leave --bone out",
        )
    bone = read_mesh(bone_path, scale=factor, kind="skull").mesh
    inputs.append({"role": "bone", "file": Path(bone_path).name, "sha256": bone_sha})
    return bone


def _write_pack(
    folder: Path,
    result: ScanFit,
    colours: ScanColours | None,
    path: Path,
    progress: Progress | None,
    extra: Callable[[Path, ScanFit], list[Path]] | None,
) -> list[Path]:
    """Write the pack of ``result`` into the staged ``folder``: the template, the detail
    layer, the scan's ``colours`` carried onto the fitted skin (vertex colours and a
    texture atlas), ``fit_report.json`` (the scan file ``path``) and ``extra``'s files."""
    from workbench.core.colour_transfer import transfer_colours
    from workbench.io.skin_colour_export import write_coloured_skin
    from workbench.io.skin_detail_export import write_skin_detail
    from workbench.io.template_pack import export_template, write_head_obj

    files = export_template(result.head, folder)
    if result.detail is not None:
        files += write_skin_detail(folder, result.detail, result.head.skin)
    if colours is not None and result.scan is not None:
        say = progress or (lambda _m: None)
        say("carrying the scan's colour onto the fitted skin ...")
        index = MeshIndex.shared(result.scan)
        skin_rgb = transfer_colours(result.head.skin, result.scan, colours, index=index)
        files += write_coloured_skin(
            folder,
            result.head.skin,
            skin_rgb,
            atlas_size=COLOUR_ATLAS_SIZE,
            scan=result.scan,
            scan_colours=colours,
            index=index,
        )
        # head.obj again, now that the folder holds the skin's own atlas (its map_Kd)
        files += [f for f in write_head_obj(result.head, folder) if f not in files]
        result.figures["colour"] = {
            "kind": skin_rgb.kind,
            "observed_fraction": round(float(skin_rgb.observed_fraction), 4),
            "atlas_size": COLOUR_ATLAS_SIZE,
        }
    report = write_json_atomic(
        folder / "fit_report.json",
        {
            "template_id": result.head.template_id,
            "scan": path.name,
            "mirrored_input": result.mirrored_input,
            "input_to_head": result.input_to_head.tolist(),
            "warnings": list(result.warnings),
            **result.figures,
        },
    )
    more = [] if extra is None else extra(folder, result)
    return [*files, report, *more]


def _working_colours(
    colours: ScanColours | None, file_mesh: Mesh, prepared: PreparedScan
) -> ScanColours | None:
    """The file's colours made to fit the working scan
    (:func:`~workbench.services.scan_fit.checks.prepare_scan`)."""
    from workbench.io.scan_colours import colours_on_working_scan

    if colours is None:
        return None
    return colours_on_working_scan(
        colours, file_mesh.vertices, prepared.mesh, prepared.vertex_of, prepared.face_source
    )
