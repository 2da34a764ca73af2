"""Length units of mesh files: detection from size, explicit conversion.

Mesh files carry no units.  The workbench works in millimetres, so a mesh
read from disk is checked for plausibility: the largest bounding-box extent of
an adult or child head or skull is roughly 100-350 mm (a face-only scan at
least 60 mm).  :func:`detect_units` asks which of mm / cm / m / inch makes
that extent plausible and explains its reasoning in a sentence; nothing here
rescales silently.  The caller applies :func:`resolve_units` (the user's
``--units``) or :func:`scale_to_reference_length` (a known anatomical
length) explicitly.

Pure numpy; no file access.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from workbench.core.errors import InputError, UnitsError
from workbench.core.mesh import Mesh

#: millimetres per unit
UNIT_SCALES: dict[str, float] = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
UNIT_NAMES: dict[str, str] = {
    "mm": "millimetres",
    "cm": "centimetres",
    "m": "metres",
    "in": "inches",
}
#: plausible largest extent in mm, and a typical value used to rank ambiguous guesses
PLAUSIBLE_EXTENT_MM: dict[str, tuple[float, float, float]] = {
    "head": (100.0, 350.0, 230.0),
    "skull": (100.0, 350.0, 190.0),
    "face": (60.0, 350.0, 180.0),
}
_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class UnitsReport:
    """What the size of a mesh says about its units.

    Attributes
    ----------
    kind : str
        "head", "skull" or "face": the object the size was judged against.
    largest_extent : float
        Largest bounding-box side in file units (NaN for an empty mesh).
    guess : str
        "mm", "cm", "m", "in" or "unknown".
    scale_to_mm : float or None
        Factor taking file units to mm for ``guess`` (None if unknown).
    plausible_in_mm : bool
        True when the file's numbers already look like millimetres.
    message : str
        A sentence for the user explaining the judgement.
    candidates : tuple of (unit, mm) pairs
        The largest extent in mm under every unit interpretation.
    confirmed : str or None
        How the user settled the units ("--units cm", "--scale 2.5", ...), if
        they did.
    """

    kind: str
    largest_extent: float
    guess: str
    scale_to_mm: float | None
    plausible_in_mm: bool
    message: str
    candidates: tuple[tuple[str, float], ...] = ()
    confirmed: str | None = None

    @property
    def needs_confirmation(self) -> bool:
        """True when the data do not look like mm and the user has not said otherwise."""
        return self.confirmed is None and not self.plausible_in_mm

    def confirm(self, how: str) -> UnitsReport:
        """Copy of this report recording that the user settled the units."""
        return replace(self, confirmed=how)


def _check_kind(kind: str) -> tuple[float, float, float]:
    try:
        return PLAUSIBLE_EXTENT_MM[kind]
    except KeyError:
        raise InputError(
            "kind", f"unknown object kind {kind!r}", "use head, skull or face"
        ) from None


def detect_units_from_extent(largest_extent: float, kind: str = "head") -> UnitsReport:
    """Judge units from the largest bounding-box side (file units); see :func:`detect_units`."""
    lo, hi, typical = _check_kind(kind)
    ext = float(largest_extent)
    if not math.isfinite(ext) or ext <= 0:
        return UnitsReport(
            kind,
            ext,
            "unknown",
            None,
            False,
            "the mesh has no finite size, so its units cannot be judged",
        )
    candidates = tuple((u, ext * s) for u, s in UNIT_SCALES.items())
    plausible = [(u, mm) for u, mm in candidates if lo <= mm <= hi]
    size = f"largest extent {ext:.4g}"
    expected = f"(a {kind} is roughly {lo:.0f}-{hi:.0f} mm)"
    if any(u == "mm" for u, _ in plausible):
        return UnitsReport(
            kind, ext, "mm", 1.0, True, f"{size}: plausible as millimetres {expected}", candidates
        )
    too = "far too small" if ext < lo else "far too large"
    parts = [f"{size}: as millimetres that is {too} for a {kind} {expected}"]
    if plausible:
        plausible.sort(key=lambda c: abs(math.log(c[1] / typical)))
        best = plausible[0][0]
        for unit, mm in plausible:
            parts.append(f"as {UNIT_NAMES[unit]} it would be {mm:.0f} mm")
        parts.append(
            f"most likely {UNIT_NAMES[best]}; confirm with --units {best}, or give --scale "
            "or a reference length"
        )
        return UnitsReport(kind, ext, best, UNIT_SCALES[best], False, "; ".join(parts), candidates)
    parts.append(
        "no common unit (mm, cm, m, inch) gives a plausible size; give --scale or scale to "
        "a reference length"
    )
    return UnitsReport(kind, ext, "unknown", None, False, "; ".join(parts), candidates)


def detect_units(mesh: Mesh | np.ndarray, kind: str = "head") -> UnitsReport:
    """Guess the length unit of a mesh from its bounding-box size.

    Parameters
    ----------
    mesh : Mesh or (n, 3) array
        Geometry in unknown file units.
    kind : {"head", "skull", "face"}
        What the mesh shows; sets the plausible largest extent
        (head/skull 100-350 mm, face 60-350 mm).

    Returns
    -------
    UnitsReport
        ``guess`` is "mm" when the numbers are plausible millimetres,
        otherwise the unit (cm, m, in) whose conversion is plausible and
        closest to a typical size, or "unknown".
    """
    if isinstance(mesh, Mesh):
        extent = mesh.extent
    else:
        pts = np.asarray(mesh, dtype=np.float64).reshape(-1, 3)
        pts = pts[np.isfinite(pts).all(axis=1)]
        extent = pts.max(axis=0) - pts.min(axis=0) if len(pts) else np.full(3, np.nan)
    largest = float(np.max(extent)) if np.all(np.isfinite(extent)) else float("nan")
    return detect_units_from_extent(largest, kind)


def resolve_units(
    report: UnitsReport, requested: str | None = "auto", *, source: str = "mesh"
) -> float:
    """Scale factor (file units to mm) for the user's ``--units`` choice.

    Parameters
    ----------
    report : UnitsReport
        From :func:`detect_units`.
    requested : {"auto", "mm", "cm", "m", "in"} or None
        None/"auto" accepts the data as mm only when they look like mm.
    source : str
        File name used in error messages.

    Raises
    ------
    UnitsError
        "auto" for data that do not look like mm (the message explains why
        and suggests ``--units``).
    InputError
        An unknown unit name.
    """
    if requested in (None, "auto"):
        if report.needs_confirmation:
            best = f"--units {report.guess}" if report.guess in UNIT_SCALES else "--scale FACTOR"
            raise UnitsError(source, f"units unclear: {report.message}", f"rerun with {best}")
        return 1.0
    return unit_scale(requested)


def check_units_choice(
    units: str | None,
    scale: float | None,
    *,
    units_option: str = "--units",
    scale_option: str = "--scale",
) -> None:
    """Refuse a unit name together with a scale factor: one of them would be ignored.

    ``units`` None or "auto" with any ``scale`` is fine, as is a unit without a scale.
    """
    if scale is not None and units not in (None, "auto"):
        shown = f"{scale:g}" if isinstance(scale, (int, float)) else repr(scale)
        raise InputError(
            f"{units_option} {units} with {scale_option} {shown}",
            "give either units or a scale factor, not both",
            f"{units_option} {units} means {UNIT_SCALES.get(units, '?')} mm per "
            f"unit; {scale_option} sets the mm per unit itself",
        )


def unit_scale(unit: str) -> float:
    """Millimetres per ``unit`` ("mm", "cm", "m", "in"; "inch"/"inches" accepted).

    Raises
    ------
    InputError
        An unknown unit name.
    """
    key = str(unit).strip().lower()
    key = {"inch": "in", "inches": "in"}.get(key, key)
    if key not in UNIT_SCALES:
        raise InputError("--units", f"unknown unit {unit!r}", "use mm, cm, m or in")
    return UNIT_SCALES[key]


def reference_scale_factor(mesh: Mesh, target_mm: float, axis: int | str | None = None) -> float:
    """Factor making the largest extent (or the extent along ``axis``) equal ``target_mm``."""
    target = float(target_mm)
    if not math.isfinite(target) or target <= 0:
        raise InputError("reference length", f"must be a positive number of mm, got {target_mm!r}")
    extent = mesh.extent
    if axis is None:
        current = float(np.max(extent))
    else:
        index = _AXES.get(str(axis).lower(), axis)
        if index not in (0, 1, 2):
            raise InputError("axis", f"unknown axis {axis!r}", "use 0/1/2 or x/y/z")
        current = float(extent[int(index)])
    if not math.isfinite(current) or current <= 0:
        raise InputError("mesh", "has no extent along the reference direction, cannot scale it")
    return target / current


def scale_to_reference_length(mesh: Mesh, target_mm: float, axis: int | str | None = None) -> Mesh:
    """Scale a unitless mesh so a known length comes out right.

    Parameters
    ----------
    mesh : Mesh
        Geometry in arbitrary units.
    target_mm : float
        Desired length in mm, e.g. 185 for an adult skull's
        glabella-opisthocranion length.
    axis : {None, 0, 1, 2, "x", "y", "z"}
        None uses the largest bounding-box extent, otherwise the extent along
        that axis (the skull sample's length is its z extent).

    Returns
    -------
    Mesh
        Uniformly scaled about the origin (vertices in mm).
    """
    return mesh.scaled(reference_scale_factor(mesh, target_mm, axis))
