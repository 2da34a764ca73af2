"""Checks that refuse bad skulls and landmarks before any work starts.

Units mm.  Every check raises :class:`~workbench.core.errors.InputError`
naming the file (or the option) and the problem in plain words; the bounds
are the module constants of :mod:`workbench.core.limits`.  The checks are
cheap (a bounding box, an edge count, one closest-point query per
landmark), so the command line, scripts and the window run them before a
fit that would take seconds and end in a misleading error or a garbage face.

- :func:`check_skull_mesh`: size (a skull is 100-350 mm; every side at least
  :data:`~workbench.core.limits.MIN_SKULL_THICKNESS_MM`), enough triangles,
  a mostly manifold surface, finite vertices.
- :func:`check_landmark_geometry`: bilateral landmarks that coincide (both
  porions typed as one point), landmarks all on one line.
- :func:`check_landmarks_on_skull`: landmarks far from the skull surface
  (the LPS/RAS mix-up, another frame or units), with the distances.

The checks of a fit's settings and of its face are in
:mod:`workbench.services.reconstruction.fit_checks`.
"""

from __future__ import annotations

from os import PathLike
from typing import Any

import numpy as np

from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.limits import (
    COINCIDENT_MM,
    COLLINEAR_MM,
    LANDMARK_OFF_SURFACE_MM,
    MIN_SKULL_THICKNESS_MM,
    MIN_SKULL_TRIANGLES,
    OFF_SURFACE_FRACTION,
)
from workbench.core.mesh import Mesh
from workbench.core.units import PLAUSIBLE_EXTENT_MM

#: refuse a skull when more than this fraction of its edges is non-manifold
MAX_NONMANIFOLD_FRACTION = 0.01

Source = str | PathLike[str]


def _sizes(extent: np.ndarray) -> str:
    return " x ".join(f"{v:.4g}" for v in extent)


def check_skull_mesh(mesh: Mesh, source: Source, *, units_note: str | None = None) -> None:
    """Refuse a mesh that cannot be a skull in mm (see the module docstring).

    ``units_note`` says how the user set the units (e.g. ``"--units cm"``),
    for the message about a size that does not fit.
    """
    nonfinite = int((~np.isfinite(mesh.vertices)).any(axis=1).sum())
    if nonfinite:
        raise InputError(
            source, f"{nonfinite} vertices of {mesh.n_vertices} have NaN or infinite coordinates"
        )
    if mesh.n_faces < MIN_SKULL_TRIANGLES:
        raise InputError(
            source,
            f"has only {mesh.n_faces} triangles; a skull surface has "
            f"thousands (at least {MIN_SKULL_TRIANGLES})",
            "is this the right file?",
        )
    extent = mesh.extent
    lo, hi, _ = PLAUSIBLE_EXTENT_MM["skull"]
    largest = float(extent.max())
    how = f" after {units_note}" if units_note else ""
    if not lo <= largest <= hi:
        raise InputError(
            source,
            f"the skull is {_sizes(extent)} mm{how} (largest side "
            f"{largest:.0f} mm); a skull is {lo:.0f}-{hi:.0f} mm",
            "check --units / --scale: the file's numbers are not in the units given",
        )
    if float(extent.min()) < MIN_SKULL_THICKNESS_MM:
        raise InputError(
            source,
            f"the skull is flat: {_sizes(extent)} mm, thinner than "
            f"{MIN_SKULL_THICKNESS_MM:g} mm in one direction",
            "a skull (even a mandible alone) has depth in every direction; the "
            "file holds a plane, a line or a projection",
        )
    counts = mesh.edge_face_counts
    bad = int((counts > 2).sum())
    if len(counts) and bad > MAX_NONMANIFOLD_FRACTION * len(counts):
        raise InputError(
            source,
            f"{bad} of {len(counts)} edges are non-manifold (shared by "
            "more than 2 triangles); the surface is not a usable skull",
            "repair it first, e.g. 'workbench mesh convert --clean'",
        )


def check_landmark_geometry(landmarks: LandmarkSet, source: Source) -> None:
    """Refuse coinciding left/right landmarks and landmarks that all lie on one line."""
    defined = {lm.code: np.asarray(lm.position, float) for lm in landmarks if lm.is_defined}
    for code, p in defined.items():
        if not code.endswith("_l"):
            continue
        other = defined.get(code[:-2] + "_r")
        if other is not None and float(np.linalg.norm(p - other)) < COINCIDENT_MM:
            name = "porions" if code == "po_l" else f"{code} and {code[:-2]}_r"
            raise InputError(
                source,
                f"the left and right {name} coincide "
                f"({code} and {code[:-2]}_r are "
                f"{float(np.linalg.norm(p - other)):.2f} mm apart)",
                "one side was typed twice; place each side on its own",
            )
    if len(defined) >= 3:
        pts = np.stack(list(defined.values()))
        spread = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False) / np.sqrt(len(pts))
        if spread[1] < COLLINEAR_MM:
            raise InputError(
                source,
                f"the {len(pts)} landmarks lie on a line (spread "
                f"{spread[0]:.1f} mm along it, {spread[1]:.2f} mm across)",
                "the coordinates are damaged or were exported along one axis",
            )


def _distances(index: Any, points: np.ndarray) -> np.ndarray:
    return np.asarray(index.closest_points(points).distances, dtype=float)


def check_landmarks_on_skull(mesh: Mesh, landmarks: LandmarkSet, source: Source) -> None:
    """Refuse landmarks of which most lie far from the skull surface.

    "Far" is :data:`~workbench.core.limits.LANDMARK_OFF_SURFACE_MM`; the
    check fires when at least :data:`~workbench.core.limits.OFF_SURFACE_FRACTION`
    of the defined landmarks are that far.  The message gives the count and
    the median distance and, when negating x and y (the LPS <-> RAS flip)
    puts them on the surface, says so.
    """
    from workbench.core.spatial import MeshIndex

    defined = [lm for lm in landmarks if lm.is_defined]
    if not defined:
        return
    pts = np.stack([lm.position for lm in defined])
    if not np.isfinite(pts).all():
        raise InputError(source, "landmark coordinates are not finite numbers")
    index = MeshIndex(mesh)
    dist = _distances(index, pts)
    off = dist > LANDMARK_OFF_SURFACE_MM
    if off.sum() == 0 or off.mean() < OFF_SURFACE_FRACTION:
        return
    n, m = int(off.sum()), len(defined)
    flipped = _distances(index, pts * np.array([-1.0, -1.0, 1.0]))
    hint = (
        "if the file's coordinates are LPS/RAS flipped (x and y negated), convert them "
        "with 'workbench landmarks convert --coordinate-system', and check that the "
        "landmarks belong to this skull, in its frame and units"
    )
    if np.median(flipped) <= LANDMARK_OFF_SURFACE_MM < np.median(dist):
        hint = (
            "with x and y negated they lie on the skull (median "
            f"{np.median(flipped):.1f} mm): the file's coordinates are LPS/RAS flipped; "
            "fix the file's coordinate system (workbench landmarks convert)"
        )
    worst = ", ".join(f"{defined[i].code} {dist[i]:.0f} mm" for i in np.argsort(-dist)[:3])
    raise InputError(
        source,
        f"{n} of {m} skull landmarks are more than "
        f"{LANDMARK_OFF_SURFACE_MM:g} mm from the skull surface (median "
        f"{np.median(dist):.1f} mm; farthest: {worst})",
        hint,
    )
