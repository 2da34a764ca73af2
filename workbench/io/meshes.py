"""Read and write triangle meshes (PLY, STL, OBJ, legacy VTK, VTP) without VTK.

Reading returns a :class:`MeshReadResult`: the mesh in millimetres plus a
:class:`~workbench.core.units.UnitsReport` saying whether the numbers look
like millimetres.  Units are never changed silently: with ``units="auto"``
the mesh is returned as stored and ``result.units.needs_confirmation`` tells
the caller to ask; ``units="cm"`` (etc.) or ``scale=`` convert explicitly.

Frame: the workbench's mesh coordinates are the frame its landmark files
(``.mrk.json``, ``.fcsv``) call RAS.  Every writer puts 3D Slicer's
``SPACE=RAS`` tag in the header (Slicer takes an untagged mesh as LPS and
would show it turned 180 degrees about the z axis against the landmarks);
a file tagged ``SPACE=LPS`` (Slicer's default when it saves) is read with x
and y negated.  An untagged file is taken as it is.

Writing is atomic: the file is written beside the target under a temporary
name and moved into place with :func:`os.replace`, so a failed write never
leaves a half-written or clobbered target.  Written files state
``units: mm`` and ``SPACE=RAS`` where the format has room for them.

Every problem with an input file raises
:class:`~workbench.core.errors.InputError` naming the file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from types import ModuleType

import numpy as np

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.core.units import (
    UNIT_SCALES,
    UnitsReport,
    check_units_choice,
    detect_units,
    detect_units_from_extent,
    unit_scale,
)
from workbench.io.atomic import write_bytes_atomic
from workbench.io.mesh_formats import obj, ply, stl, vtk_legacy, vtp
from workbench.io.mesh_formats._common import space_in

_FORMATS: dict[str, ModuleType] = {
    ".ply": ply,
    ".stl": stl,
    ".obj": obj,
    ".vtk": vtk_legacy,
    ".vtp": vtp,
}
SUPPORTED_EXTENSIONS: tuple[str, ...] = tuple(_FORMATS)


@dataclass(frozen=True)
class MeshReadResult:
    """A mesh read from disk.

    Attributes
    ----------
    mesh : Mesh
        Vertices in mm (file units times ``scale_applied``).
    units : UnitsReport
        Judgement of the file's units from its size; ``units.needs_confirmation``
        is True when the numbers do not look like mm and the caller gave no
        units or scale.
    source_path : Path
        The file that was read.
    messages : tuple of str
        Notes for the user (polygons split, vertices merged, units unclear, ...).
    scale_applied : float
        Factor applied to the file's numbers (1.0 unless units/scale were given).
    format : str
        File extension that chose the reader, e.g. ".ply".
    space : {"RAS", "LPS"}, optional
        The coordinate system the file's header names with 3D Slicer's
        ``SPACE=`` tag; None when it names none.  An LPS file's x and y are
        negated on reading, so ``mesh`` is always in the RAS sense the
        workbench's mesh frame and landmark files share.
    """

    mesh: Mesh
    units: UnitsReport
    source_path: Path
    messages: tuple[str, ...]
    scale_applied: float = 1.0
    format: str = ""
    space: str | None = None


def _format_for(path: Path, action: str) -> ModuleType:
    ext = path.suffix.lower()
    if ext not in _FORMATS:
        shown = f"'{path.suffix}'" if path.suffix else "no extension"
        raise InputError(
            path,
            f"cannot {action} mesh files with {shown}",
            f"supported extensions: {', '.join(SUPPORTED_EXTENSIONS)}",
        )
    return _FORMATS[ext]


#: x and y negated: 3D Slicer's LPS <-> RAS (a rotation by 180 degrees about z)
LPS_TO_RAS = np.array([-1.0, -1.0, 1.0])
#: how much of a file :func:`file_space` reads to find the tag (the header's start)
_SPACE_SNIFF_BYTES = 65536


def file_space(path: str | PathLike[str]) -> str | None:
    """The ``SPACE=`` tag a mesh file's header gives ("RAS" / "LPS"), or None.

    A cheap look at the start of the file, for what depends on how
    :func:`read_mesh` turns the file (an LPS file is read with x and y
    negated): directions and points a user gives "in the file's
    coordinates" (``--anterior``, MeshLab ``.pp`` points) are turned the
    same way with :func:`to_read_frame`.  A VTP file's tag sits in its field
    data and is read here only from an ASCII file; None for a missing file.
    """
    p = Path(path)
    try:
        with p.open("rb") as fh:
            head = fh.read(_SPACE_SNIFF_BYTES)
    except OSError:
        return None
    if p.suffix.lower() == ".vtp":
        try:
            return vtp.read(p, p.read_bytes()).space
        except (InputError, OSError, ValueError):
            return None
    if p.suffix.lower() == ".ply":
        end = head.find(b"end_header")
        head = head[: end if end >= 0 else len(head)]
    return space_in(head)


def to_read_frame(vectors: np.ndarray, space: str | None) -> np.ndarray:
    """Points or directions given in a file's own numbers, in the frame :func:`read_mesh`
    returns that file in (x and y negated for an LPS-tagged file; else unchanged)."""
    v = np.asarray(vectors, dtype=np.float64)
    return v * LPS_TO_RAS if space == "LPS" else v


def _load_bytes(path: Path) -> bytes:
    if not path.exists():
        raise InputError(path, "file not found", "check the path and spelling")
    if path.is_dir():
        raise InputError(path, "is a folder, not a mesh file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(path, f"cannot be read ({exc.strerror or exc})") from None
    if not data:
        raise InputError(path, "the file is empty (0 bytes)")
    return data


def _check_scale(path: Path, units: str, scale: float | None) -> float | None:
    if scale is None:
        return None
    check_units_choice(units, scale)
    try:
        value = float(scale)
    except (TypeError, ValueError):
        raise InputError(
            path, f"the scale factor (--scale) must be a number, got {scale!r}"
        ) from None
    if not math.isfinite(value) or value <= 0:
        raise InputError(
            path,
            f"the scale factor (--scale) must be a positive number of mm "
            f"per file unit, got {scale!r}",
        )
    return value


def read_mesh(
    path: str | PathLike[str],
    units: str = "auto",
    scale: float | None = None,
    *,
    kind: str = "head",
    allow_nonfinite: bool = False,
) -> MeshReadResult:
    """Read a triangle mesh; the format is chosen by the file extension.

    Parameters
    ----------
    path : path-like
        ``.ply``, ``.stl``, ``.obj``, ``.vtk`` (legacy polydata) or ``.vtp``.
    units : {"auto", "mm", "cm", "m", "in"}
        Units of the numbers in the file.  "auto" keeps them unscaled and
        flags (``result.units.needs_confirmation``) data that do not look
        like mm; a unit name converts to mm (e.g. "cm" multiplies by 10).
    scale : float, optional
        Explicit factor from file units to mm (instead of ``units``).
    kind : {"head", "skull", "face"}
        What the mesh shows; sets the plausible size used by unit detection.
    allow_nonfinite : bool
        Keep vertices with NaN or infinite coordinates (for inspecting a
        damaged file); by default such a file is refused with their count.

    Returns
    -------
    MeshReadResult

    Raises
    ------
    InputError
        Missing file, unsupported extension, or a file that cannot be parsed
        (truncated, non-numeric, indices out of range, no triangles, NaN or
        infinite coordinates, ...), or both ``units`` and ``scale``.
    """
    path = Path(path)
    module = _format_for(path, "read")
    detect_units_from_extent(1.0, kind)  # reject an unknown kind before reading
    factor = _check_scale(path, units, scale)
    if factor is None and units not in ("auto", None):
        factor = unit_scale(units)
    data = _load_bytes(path)
    with np.errstate(all="ignore"):  # damaged numbers (NaN, overflow) are reported, not warned
        parsed = module.read(path, data)
    vertices = parsed.vertices
    if parsed.space == "LPS":  # Slicer's tag: x and y negated into RAS (a rotation: same winding)
        vertices = vertices * LPS_TO_RAS
    raw = Mesh(vertices, parsed.faces)
    if not allow_nonfinite:
        _refuse_nonfinite(path, raw)
    report = detect_units(raw, kind)
    messages = list(parsed.messages)
    if parsed.space == "LPS":
        messages.append(
            "the file says SPACE=LPS (3D Slicer): x and y negated into RAS, and so are "
            "directions given for it (--anterior/--superior/--left) and MeshLab .pp points"
        )
    if factor is None:
        factor = 1.0
        if report.needs_confirmation:
            messages.append(f"units unclear: {report.message}")
    else:
        how = f"--scale {factor:g}" if scale is not None else f"--units {units}"
        report = report.confirm(how)
        scaled_report = detect_units(raw.vertices * factor, kind)
        if not scaled_report.plausible_in_mm:
            messages.append(
                f"after {how} the largest extent is {report.largest_extent * factor:.4g} mm, "
                f"which is unusual for a {kind}; check the units"
            )
    mesh = raw if factor == 1.0 else raw.scaled(factor)
    return MeshReadResult(
        mesh, report, path, tuple(messages), factor, path.suffix.lower(), parsed.space
    )


def _refuse_nonfinite(path: Path, mesh: Mesh) -> None:
    """An :class:`InputError` naming the file and the count of NaN / infinite vertices."""
    bad = ~np.isfinite(mesh.vertices)
    if not bad.any():
        return
    rows = bad.any(axis=1)
    nan = int(np.isnan(mesh.vertices).any(axis=1).sum())
    kinds = " and ".join(k for k, n in (("NaN", nan), ("infinite", int(rows.sum()) - nan)) if n)
    first = ", ".join(str(i) for i in np.flatnonzero(rows)[:5])
    raise InputError(
        path,
        f"{int(rows.sum())} vertices of {mesh.n_vertices} have {kinds} "
        f"coordinates (first: vertex {first})",
        "the file is damaged or was exported incorrectly; repair or export it "
        "again ('workbench mesh info' shows the damage)",
    )


def write_mesh(
    path: str | PathLike[str], mesh: Mesh, binary: bool = True, *, space: str = "RAS"
) -> Path:
    """Write a mesh (vertices in mm) atomically; the format follows the extension.

    Parameters
    ----------
    path : path-like
        Target file: ``.ply``, ``.stl``, ``.obj``, ``.vtk`` or ``.vtp``.
    mesh : Mesh
        Vertices in mm.
    binary : bool
        Binary encoding where the format has one (PLY little endian, STL,
        legacy VTK big endian, VTP appended raw); False gives ascii (VTP:
        inline base64).  OBJ is always text.
    space : {"RAS", "LPS"}
        The frame the header's ``SPACE=`` tag names for 3D Slicer: "RAS" (the
        workbench's mesh frame, shared with its landmark files) unless the
        vertices are LPS numbers (a CT surface in the volume's DICOM frame).

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    InputError
        Unsupported extension, missing folder, or the file cannot be written.
    """
    path = Path(path)
    module = _format_for(path, "write")
    if not isinstance(mesh, Mesh):
        raise InputError(path, f"expected a Mesh to write, got {type(mesh).__name__}")
    if not path.parent.is_dir():
        raise InputError(path, "the folder does not exist", "create it first")
    if path.is_dir():
        raise InputError(path, "is a folder, cannot write a mesh file there")
    payload = module.encode(mesh.vertices, np.asarray(mesh.faces), binary=binary, space=space)
    try:
        write_bytes_atomic(path, payload)
    except OSError as exc:
        raise InputError(path, f"cannot be written ({exc.strerror or exc})") from None
    return path


__all__ = [
    "SUPPORTED_EXTENSIONS",
    "UNIT_SCALES",
    "MeshReadResult",
    "read_mesh",
    "write_mesh",
]
