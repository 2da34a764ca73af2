"""Plausibility bounds for user inputs, in one place (lengths in mm).

A value outside these bounds is not a forensic finding but a typing slip,
a wrong unit or a broken file, so the workbench refuses it with a message
naming the option or file and the bound instead of computing a garbage
result.  The bounds are sanity limits, deliberately generous: each comment
says why a real case cannot reach it.

Pure Python and numpy; no file access.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from workbench.core.errors import InputError

#: soft-tissue depth (mm), 0 < d <= MAX: the thickest facial tissue of obese adults
#: (cheek, submental) stays well under 60 mm; more is a unit slip (cm read as mm x 10...)
MAX_TISSUE_DEPTH_MM = 60.0
#: SD of a table depth (mm): a spread larger than the largest plausible depth is garbage
MAX_TISSUE_SD_MM = MAX_TISSUE_DEPTH_MM
#: thickness factor of a face region (x the table's tissue): a third to three times
#: spans emaciated to obese faces; beyond it the factor is a slip
REGION_FACTOR_RANGE = (0.3, 3.0)
#: build k (mean + k SD): 4 SD covers 99.99 % of a normal population; beyond it the
#: table is being extrapolated, not read
MAX_BUILD_SD = 4.0
#: a body-mass index outside this is taken as a typing error (kg/m²)
BMI_RANGE = (12.0, 70.0)
#: uncertainty-ensemble fits: the spread map settles by ~50 draws, one draw takes ~0.5 s,
#: so 500 is minutes already (1e8 would run for years)
MAX_ENSEMBLE = 500
#: CT / MR voxel size (mm): clinical and micro CT lie within 0.05-20 mm; 0 is an unset
#: header field, km-size voxels a unit slip
VOXEL_MM_RANGE = (0.05, 20.0)
#: decimation target (triangles): below 1,000 a skull or head loses its anatomy, above
#: 5,000,000 the mesh is larger than any CT iso-surface needs
TARGET_TRIANGLES_RANGE = (1_000, 5_000_000)
#: Taubin smoothing iterations: a few tens smooth a CT surface; thousands melt it
MAX_SMOOTH_ITERATIONS = 500
#: every extent of a skull (mm): even a mandible alone is 30 mm or more in every direction,
#: so a thinner "skull" is flat (a plane, a line) or in the wrong units
MIN_SKULL_THICKNESS_MM = 20.0
#: a skull mesh needs at least this many triangles to carry any anatomy at all
MIN_SKULL_TRIANGLES = 100
#: the reconstructed face's bounding box against the skull's: every side of the face at least
#: the low factor x the skull's smallest side (the skin covers the bone: a face 29 mm deep
#: over a 150 x 180 x 200 mm skull is a failed fit; the smallest side, as a bone surface from
#: CT may carry vertebrae or shoulders), and none above the high factor x the skull's largest
#: side (the reference head carries its neck, and the boxes are the file's axes, in which a
#: head may lie tilted: over the headsq bone, 168 mm at most with its vault cut, the face
#: spans 336-339 mm along the scanner's axis, 2.0 x, and the 2.0 this bound was before refused
#: it after a 0.5 mm change of the reference skin; a runaway fit is several times larger)
FACE_TO_SKULL_EXTENT_RANGE = (0.8, 2.5)
#: a skull landmark farther than this (mm) from the skull surface is not on the bone
LANDMARK_OFF_SURFACE_MM = 10.0
#: refuse the landmarks when at least this fraction of them is off the surface
OFF_SURFACE_FRACTION = 0.5
#: two landmarks closer than this (mm) coincide (e.g. both porions typed as one point)
COINCIDENT_MM = 1.0
#: landmarks whose second principal spread is below this (mm) lie on a line
COLLINEAR_MM = 2.0


def finite_number(value: Any, name: str) -> float:
    """``value`` as a float, or an :class:`InputError` naming ``name``."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(name, f"{value!r} is not a number") from None
    if isinstance(value, bool) or not math.isfinite(number):
        raise InputError(name, f"must be a finite number, got {value!r}")
    return number


def check_range(
    value: Any,
    name: str,
    lo: float | None = None,
    hi: float | None = None,
    *,
    unit: str = "",
    low_open: bool = False,
    why: str = "",
) -> float:
    """``value`` as a finite float within ``[lo, hi]`` (``(lo, hi]`` with ``low_open``).

    Raises an :class:`InputError` naming ``name``, the value and the bound.
    """
    number = finite_number(value, name)
    below = lo is not None and (number <= lo if low_open else number < lo)
    above = hi is not None and number > hi
    if below or above:
        u = f" {unit}" if unit else ""
        if lo is not None and hi is not None:
            bound = f"{'above' if low_open else 'at least'} {lo:g} and at most {hi:g}{u}"
        elif lo is not None:
            bound = f"{'above' if low_open else 'at least'} {lo:g}{u}"
        else:
            bound = f"at most {hi:g}{u}"
        raise InputError(name, f"{value!r} is out of range: must be {bound}", why or None)
    return number


def check_count(value: Any, name: str, lo: int, hi: int, why: str = "") -> int:
    """An integer within ``[lo, hi]`` (an :class:`InputError` naming ``name`` otherwise)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        number = finite_number(value, name)
        if number != int(number):
            raise InputError(name, f"must be a whole number, got {value!r}")
        value = int(number)
    if not lo <= int(value) <= hi:
        raise InputError(name, f"{value!r} is out of range: must be {lo}-{hi}", why or None)
    return int(value)


def check_tissue_depth(value: Any, name: str) -> float:
    """A soft-tissue depth in mm: ``0 < d <= MAX_TISSUE_DEPTH_MM``."""
    return check_range(
        value,
        name,
        0.0,
        MAX_TISSUE_DEPTH_MM,
        unit="mm",
        low_open=True,
        why=f"no face has soft tissue thicker than {MAX_TISSUE_DEPTH_MM:g} mm; check the units",
    )


def check_build_sd(k: float, name: str = "--build") -> float:
    """A build k (mean + k SD) within ``±MAX_BUILD_SD``."""
    return check_range(
        k,
        name,
        -MAX_BUILD_SD,
        MAX_BUILD_SD,
        unit="SD",
        why=f"a build is mean + k SD with k within ±{MAX_BUILD_SD:g} SD",
    )


def check_voxel_size(spacing_mm: Any, source: Any) -> np.ndarray:
    """Voxel sizes (mm) within :data:`VOXEL_MM_RANGE`, else an error naming the file."""
    spacing = np.asarray(spacing_mm, dtype=np.float64).reshape(-1)
    lo, hi = VOXEL_MM_RANGE
    shown = " x ".join(f"{s:.4g}" for s in spacing)
    if not np.isfinite(spacing).all():
        raise InputError(
            source,
            f"the voxel size is not a number ({shown} mm)",
            "the header's spacing or affine is damaged",
        )
    if (spacing < lo).any() or (spacing > hi).any():
        raise InputError(
            source,
            f"voxel size {shown} mm is implausible for a CT or MR scan (expected {lo:g}-{hi:g} mm)",
            "the header's voxel size is unset or in the wrong units",
        )
    return spacing


def check_face_fits_skull(
    face_extent_mm: Any, skull_extent_mm: Any, source: str = "reconstruction"
) -> None:
    """Refuse a face whose bounding box does not fit the skull's.

    Both extents are ``(3,)`` sizes (mm) in the same frame.  Every side of
    the face must be at least the low factor of
    :data:`FACE_TO_SKULL_EXTENT_RANGE` times the skull's smallest side and
    at most the high factor times its largest side (see the constant).
    """
    face = np.asarray(face_extent_mm, dtype=np.float64).reshape(3)
    skull = np.asarray(skull_extent_mm, dtype=np.float64).reshape(3)
    lo, hi = FACE_TO_SKULL_EXTENT_RANGE
    ok = bool(
        np.isfinite(face).all()
        and np.isfinite(skull).all()
        and (face >= lo * skull.min()).all()
        and (face <= hi * skull.max()).all()
    )
    if not ok:
        sizes = " x ".join(f"{v:.1f}" for v in face)
        bone = " x ".join(f"{v:.1f}" for v in skull)
        raise InputError(
            source,
            f"the face came out {sizes} mm against a skull of {bone} mm "
            f"(each side should be at least {lo:g} x the skull's smallest side "
            f"and at most {hi:g} x its largest); the result is not a plausible "
            "face",
            "check the skull landmarks, the orientation and the depth settings",
        )


# ------------------------------------------------------------------ scan fitting (issue 29)
#: a partial face scan (a CT that ends at the upper teeth, a scan without its chin) is
#: fitted where it is and the rest inferred from the reference, when at least this share of
#: the reference face lies over the scan (not beyond its rim): below it too little is seen
#: to call the shape a face (the headsq CT cut at the upper teeth shows 61 % of it, cut at
#: the subnasale 58 %)
MIN_SCAN_FACE_COVERAGE = 0.3
#: ... and at least this share of the reference nose: the nose with the orbits or the mouth
#: around it is what fixes the pose of a part of a face
MIN_SCAN_NOSE_COVERAGE = 0.5

# ------------------------------------------------------------------ scans (fit-scan)
#: scan vertices are welded on a grid of this fraction of the scan's bounding-box
#: diagonal (0.3 µm on a 300 mm head): far below any scanner's resolution, so only copies
#: of one point merge (a triangle soup, where each triangle has its own corners, or the
#: seams a texture export splits)
SCAN_WELD_FRACTION = 1e-6
#: a scan triangle with less area than this fraction of the squared diagonal is a
#: zero-area sliver (9e-6 mm² on a 300 mm head: 1 mm long and 20 nm wide); its normal is
#: rounding noise, so it is dropped
SCAN_SLIVER_AREA_FRACTION = 1e-10
#: a scan with more triangles is simplified (quadric decimation) to this many before it is
#: oriented and fitted: 300k triangles hold ~0.5 mm detail over a head, finer than the
#: fitted skin's detail layer (~1 mm edges), and a fit on them takes about half a minute
SCAN_WORK_TRIANGLES = 300_000
#: a scan file with more triangles is refused: 20 M triangles take ~2 GB to read and weld
#: before simplification, and no face scanner needs more (a 0.1 mm grid over a whole head
#: is ~10 M)
SCAN_MAX_TRIANGLES = 20_000_000
#: a piece of the scan this far (mm, surface to surface) from the largest piece is not part
#: of the head (a stray blob, a marker, a second object on the turntable): it is left out
#: and said; nearer pieces (a loose ear, a head holder) stay
SCAN_STRAY_PIECE_MM = 30.0
#: texture images of one scan: at most this many files ...
SCAN_TEXTURE_MAX_IMAGES = 64
#: ... each at most this many pixels (16384 x 16384, the largest texture GPUs take) ...
SCAN_TEXTURE_MAX_PIXELS = 16384 * 16384
#: ... and at most this many pixels together (32 images of 8192 x 8192): each is decoded
#: once, at ~100 M pixels/s, so the limit bounds the reading time to about 20 s
SCAN_TEXTURE_MAX_TOTAL_PIXELS = 32 * 8192 * 8192
#: the textures are kept as uint8 RGB, each shrunk by a whole factor so that together they
#: hold at most this many pixels (48 MB): the fitted skin's colour atlas is 1024 x 1024,
#: so a 4096 x 4096 equivalent over the whole scan leaves the face more texels than it uses
SCAN_TEXTURE_WORK_PIXELS = 4096 * 4096
#: skin landmarks (fit-scan --landmarks) farther than this (mm) from the scan's surface are
#: not on it (a landmark over a hole of the scan lies within a few mm of its rim's surface)
SCAN_LANDMARK_OFF_MM = 20.0
#: length (s) of an animation clip (animate --clip-seconds): an expression ramps in well
#: under a second, a whole spoken take lasts minutes; ten minutes is far beyond any clip,
#: while 1e12 s (31,700 years) is a typing slip that players and editors choke on
MAX_CLIP_SECONDS = 600.0
