"""Service behind ``workbench mesh-from-ct``: CT volume -> bone or skin surface mesh.

The mesh is returned in millimetres in the volume's physical frame (LPS for
DICOM/NRRD/MetaImage, RAS for NIfTI; recorded in the result), with outward
normals.  Nothing is written to disk here; the caller saves the mesh.

When the volume is (a file of) a registered sample whose data must carry a
credit line (the NLM Visible Human CTs), the result's ``credit`` holds it
(:func:`workbench.io.samples.credit_for`, matched by SHA-256), so the caller
can show it and write it into the mesh file (PLY ``comment credit: ...``).

Progress is reported through an optional ``progress(step, fraction)``
callback (``fraction`` of the whole job, 0..1), so the service can run in a
worker thread or be wrapped in a generator by a GUI/CLI without changes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from os import PathLike
from time import perf_counter
from typing import Any

from workbench.core.isosurface import TISSUES, IsoChoice, choose_iso, extract_isosurface
from workbench.core.limits import (
    MAX_SMOOTH_ITERATIONS,
    TARGET_TRIANGLES_RANGE,
    check_count,
    finite_number,
)
from workbench.core.mesh import Mesh, ValidationReport, validate
from workbench.core.volume import Volume
from workbench.io.samples import credit_for
from workbench.io.volumes import read_volume

Progress = Callable[[str, float], None]

_READ_END = 0.1
_EXTRACT_END = 0.9


@dataclass(frozen=True)
class CTMeshResult:
    """A surface extracted from a CT volume.

    Attributes
    ----------
    mesh : Mesh
        Vertices in mm in ``frame``; outward normals.
    tissue : str
        "bone" or "skin" (the preset asked for; see ``rule`` when ``iso`` was given).
    iso : float
        Level used, in the volume's units (``units``).
    rule : str
        Why this level (HU preset, VTK convention, multi-Otsu, explicit).
    frame : str
        Physical frame of the vertices ("LPS" or "RAS").
    units : str
        Units of ``iso`` ("HU" or "unknown").
    timings_s : dict
        Wall time per step in seconds ("read", "extract", "validate", "total").
    validation : ValidationReport
        :func:`workbench.core.mesh.validate` of ``mesh``.
    stats : dict
        Extraction statistics (crop box, slab count, triangle counts, ...).
    source : str
        The input path or the volume's source.
    warnings : tuple of str
        Reader warnings (ignored series, irregular spacing, assumed frame).
    credit : str or None
        Credit line the source data require wherever they (or meshes made
        from them) are shown, e.g. "Courtesy of the U.S. National Library of
        Medicine. ..." for the Visible Human CTs; None for other data.
    iso_note : str or None
        For a bone level above the usual 300 HU: what it leaves out of the
        bone seen at 300 HU (thin bone first), and the alternative.
    """

    mesh: Mesh
    tissue: str
    iso: float
    rule: str
    frame: str
    units: str
    timings_s: dict[str, float]
    validation: ValidationReport
    stats: dict[str, Any] = field(default_factory=dict)
    source: str = ""
    warnings: tuple[str, ...] = ()
    credit: str | None = None
    iso_note: str | None = None

    @property
    def summary(self) -> str:
        """One-line validation summary (counts and problems)."""
        return self.validation.summary()

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly description (no mesh arrays)."""
        return {
            "source": self.source,
            "tissue": self.tissue,
            "iso": self.iso,
            "units": self.units,
            "rule": self.rule,
            "frame": self.frame,
            "n_vertices": self.mesh.n_vertices,
            "n_faces": self.mesh.n_faces,
            "bounds_mm": self.mesh.bounds.tolist(),
            "timings_s": dict(self.timings_s),
            "validation": self.validation.to_dict() | {"summary": self.summary},
            "stats": {k: v for k, v in self.stats.items() if k != "timings_s"},
            "warnings": list(self.warnings),
            "credit": self.credit,
            "iso_note": self.iso_note,
        }


def mesh_from_ct(
    path_or_volume: str | PathLike[str] | Volume,
    tissue: str = "bone",
    iso: float | None = None,
    target_triangles: int | None = None,
    smooth_iterations: int = 0,
    progress: Progress | None = None,
    *,
    largest_component: bool = True,
) -> CTMeshResult:
    """Extract the bone or skin surface of a CT volume.

    Parameters
    ----------
    path_or_volume : path-like or Volume
        DICOM series folder, NRRD/NHDR, MetaImage or NIfTI file, or a loaded volume.
    tissue : {"bone", "skin"}
        Preset used when ``iso`` is None (300 / -300 HU for CT in HU; see
        :func:`workbench.core.isosurface.choose_iso` for non-HU data).
    iso : float, optional
        Explicit level in the volume's units; overrides the preset.
    target_triangles : int, optional
        Decimate (quadric) to about this many triangles.
    smooth_iterations : int
        Taubin smoothing iterations (0 keeps the marching-cubes surface as is,
        the most faithful choice for measurements).
    progress : callable(step: str, fraction: float), optional
        Progress of the whole job, 0..1.
    largest_component : bool
        Keep only the largest connected piece (drops debris, the CT table,
        and a mandible that does not touch the skull at this level).

    Returns
    -------
    CTMeshResult
        ``credit`` is looked up from the input path (for a loaded volume:
        from ``volume.source`` when that is an existing path).
    """
    if tissue not in TISSUES:
        raise ValueError(f"tissue must be one of {TISSUES}, got {tissue!r}")
    check_extraction_settings(iso, target_triangles, smooth_iterations)

    def report(step: str, fraction: float) -> None:
        if progress is not None:
            progress(step, fraction)

    timings: dict[str, float] = {}
    start = perf_counter()
    report("reading volume", 0.0)
    if isinstance(path_or_volume, Volume):
        volume = path_or_volume
    else:
        volume = read_volume(path_or_volume)
    timings["read"] = round(perf_counter() - start, 4)
    report("reading volume", _READ_END)

    if iso is None:
        choice = choose_iso(volume, tissue)
    else:
        choice = IsoChoice(
            float(iso), f"explicit level {float(iso):g} {volume.units} (preset not used)"
        )

    def inner(step: str, fraction: float) -> None:
        report(step, _READ_END + (_EXTRACT_END - _READ_END) * fraction)

    t0 = perf_counter()
    result = extract_isosurface(
        volume,
        choice.iso,
        largest_component=largest_component,
        smooth_iterations=smooth_iterations,
        target_triangles=target_triangles,
        progress=inner,
    )
    timings["extract"] = round(perf_counter() - t0, 4)
    report("validating", _EXTRACT_END)
    t0 = perf_counter()
    report_ = validate(result.mesh)
    timings["validate"] = round(perf_counter() - t0, 4)
    note = _iso_note(volume, tissue, choice.iso) if tissue == "bone" else None
    timings["total"] = round(perf_counter() - start, 4)
    report("done", 1.0)
    return CTMeshResult(
        mesh=result.mesh,
        tissue=tissue,
        iso=choice.iso,
        rule=choice.rule,
        frame=result.frame,
        units=volume.units,
        timings_s=timings,
        validation=report_,
        stats=dict(result.stats),
        source=str(path_or_volume) if not isinstance(path_or_volume, Volume) else volume.source,
        warnings=tuple(volume.metadata.get("warnings", ())),
        credit=_credit(path_or_volume),
        iso_note=note,
    )


def _iso_note(volume: Volume, tissue: str, iso: float) -> str | None:
    """What a bone level above the usual 300 HU leaves out (HU data, stated or evident)."""
    from workbench.core.isosurface import HU_PRESETS, looks_like_hu, thin_bone_loss

    if volume.units != "HU" and not looks_like_hu(volume):
        return None
    usual = HU_PRESETS[tissue]
    loss = thin_bone_loss(volume, iso, usual)
    if loss is None:
        return None
    return (
        f"at {iso:g} HU, {100 * loss['thin_lost']:.0f} % of the thin bone and "
        f"{100 * loss['lost']:.0f} % of all the bone seen at {usual:g} HU are left out (thin "
        "plates go first: the orbital walls, nasal bones, sinus walls and ethmoid, where a "
        "reconstruction needs them); the usual bone level is "
        f"{usual:g} HU (--iso {usual:g})"
    )


def check_extraction_settings(
    iso: float | None, target_triangles: int | None, smooth_iterations: int = 0
) -> None:
    """Refuse a non-finite iso level, a decimation target or smoothing out of bounds.

    The bounds are :data:`~workbench.core.limits.TARGET_TRIANGLES_RANGE` and
    :data:`~workbench.core.limits.MAX_SMOOTH_ITERATIONS`; the names in the
    messages are the command-line options.
    """
    if iso is not None:
        finite_number(iso, "--iso")
    if target_triangles is not None:
        lo, hi = TARGET_TRIANGLES_RANGE
        check_count(
            target_triangles,
            "--target-triangles",
            lo,
            hi,
            why=f"fewer than {lo:,} triangles lose the anatomy; more than {hi:,} is "
            "finer than any CT needs",
        )
    check_count(
        smooth_iterations,
        "--smooth",
        0,
        MAX_SMOOTH_ITERATIONS,
        why="a few tens of iterations smooth a CT surface; thousands melt it",
    )


def _credit(path_or_volume: str | PathLike[str] | Volume) -> str | None:
    """Credit of the sample the input came from (by SHA-256), or None.

    A source that cannot be hashed (a description instead of a path, an
    unreadable file) has no known credit; the extraction itself never fails here.
    """
    source = path_or_volume.source if isinstance(path_or_volume, Volume) else path_or_volume
    if not source:
        return None
    try:
        return credit_for(source)
    except (OSError, ValueError):
        return None
