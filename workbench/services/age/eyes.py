"""The eyes of an aged head: eyeballs sized by their own growth and seated in their lids.

Units mm; heads in their Frankfort frame (x to the subject's left, y up, z
toward the face).  The eyeball grows little after early childhood (axial
length 22 mm at 3 y, 23.6 mm in adults; :mod:`workbench.services.age.growth_tables`)
while the face grows by a third, so a child's eyes are large for its face.
The landmark warp scales everything by the face's local size change; here
each eyeball is scaled instead by the eyeball curve, about its own centre
(where the warp put the orbit).  The lids are not pushed out to make room:
their corners and margins carry the palpebral-fissure norms (length, height,
canthal widths) as exact landmark targets.  Instead the globe is moved along
its gaze until the lid margin lies at the same distance from it as on the
source head (:func:`seat_eyes`), so the eye neither pokes through the lids
nor leaves a gap behind them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from workbench.model.template import TemplateHead

#: the most an eyeball is moved along its gaze to sit in its lids (mm)
MAX_SEAT_MM = 4.0
#: the gaze of the reference heads' eyes: straight ahead, +z of the head frame
GAZE = np.array([0.0, 0.0, 1.0])
#: lid skin is kept at least this far outside the globe, or as far as on the source if less (mm)
LID_CLEARANCE_MM = 0.2


def eye_owner(centres: np.ndarray, points: np.ndarray) -> np.ndarray:
    """For each point (k, 3; mm) the index of the nearest eye centre (0 left, 1 right)."""
    return np.linalg.norm(points[:, None] - centres[None], axis=2).argmin(axis=1)


def scale_eyes(head: TemplateHead, radius: float) -> TemplateHead:
    """``head`` with each eyeball scaled about its centre to the globe radius ``radius`` (mm)."""
    if not head.meshes["eyes"].n_vertices or head.eye_radius <= 0:
        return head
    factor = float(radius) / float(head.eye_radius)
    eyes = head.meshes["eyes"].vertices
    own = eye_owner(head.eye_centres, eyes)
    centre = head.eye_centres[own]
    moved = centre + factor * (eyes - centre)
    meshes = {**head.meshes, "eyes": head.meshes["eyes"].with_vertices(moved)}
    return replace(head, meshes=meshes, eye_radius=float(radius))


def _side(eye: int) -> str:
    return "l" if eye == 0 else "r"  # eye 0 is the subject's left (x > 0)


def _lid_ids(head: TemplateHead, eye: int) -> np.ndarray:
    """Skin vertices of eye ``eye``'s upper and lower lid (the ``eyelid_*`` regions)."""
    parts = [
        np.asarray(head.regions[k])
        for k in (f"eyelid_upper_{_side(eye)}", f"eyelid_lower_{_side(eye)}")
        if k in head.regions
    ]
    return np.concatenate(parts).astype(np.int64) if parts else np.zeros(0, dtype=np.int64)


def _gaps(head: TemplateHead, ids: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Distances (mm) of skin vertices ``ids`` from the globe of radius ``head.eye_radius``."""
    return np.linalg.norm(head.skin.vertices[ids] - centre, axis=1) - head.eye_radius


def rim_gap(head: TemplateHead, eye: int, centre: np.ndarray | None = None) -> float:
    """Median distance (mm) of eye ``eye``'s lid margin (the skin's opening loop) from its globe.

    ``centre`` replaces the eye's centre (mm); NaN without the opening.
    """
    rim = head.openings.get(f"eye_{_side(eye)}")
    if rim is None or not len(rim):
        return float("nan")
    c = head.eye_centres[eye] if centre is None else centre
    return float(np.median(_gaps(head, np.asarray(rim, dtype=np.int64), c)))


def _bisect(gap_at: Callable[[float], float], want: float, lo: float, hi: float) -> float:
    """The shift t in [lo, hi] (mm along the gaze) with ``gap_at(t) == want``; the gap falls
    as t grows (the globe moves forward)."""
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if gap_at(mid) > want:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _seat_shift(source: TemplateHead, aged: TemplateHead, k: int) -> float:
    """How far (mm, along :data:`GAZE`) eye ``k`` of ``aged`` moves to sit in its lids."""
    want = rim_gap(source, k)
    if not np.isfinite(want):
        return 0.0
    c = aged.eye_centres[k]

    def margin(s: float) -> float:
        return rim_gap(aged, k, c + s * GAZE)

    t = _bisect(margin, want, -MAX_SEAT_MM, MAX_SEAT_MM)
    lids = _lid_ids(source, k)
    if not len(lids):
        return t
    clear = min(float(_gaps(source, lids, source.eye_centres[k]).min()), LID_CLEARANCE_MM)

    def closest(s: float) -> float:
        return float(_gaps(aged, lids, c + s * GAZE).min())

    return _bisect(closest, clear, -MAX_SEAT_MM, t) if closest(t) < clear else t


def seat_eyes(source: TemplateHead, aged: TemplateHead) -> TemplateHead:
    """``aged`` with each eyeball moved along the gaze (+z) to sit in its lids as on ``source``.

    The lid margin (the skin's eye opening) keeps its median distance from
    the globe: a globe that grew more than the face around it moves back into
    the orbit until the lids rest on it as before, one that grew less moves
    forward -- instead of the lids being pushed out, which would change the
    palpebral fissure the facial norms set.  Then, if some lid skin came
    closer to the globe than the source's closest (or :data:`LID_CLEARANCE_MM`,
    whichever is less), the globe moves back until it does not.  Bisection on
    the shift (mm, within :data:`MAX_SEAT_MM`); the skin is not changed.
    """
    if not aged.meshes["eyes"].n_vertices or aged.eye_radius <= 0:
        return aged
    shift = np.zeros_like(aged.eye_centres)
    for k in range(len(aged.eye_centres)):
        shift[k] = _seat_shift(source, aged, k) * GAZE
    return aged.with_eyes_moved({k: shift[k] for k in range(len(shift))})


def lid_gaps(head: TemplateHead) -> dict[str, float]:
    """Distance of the eyelid skin from the globe (mm): the smallest and the median.

    Negative: lid skin inside the eyeball (the eye pokes through the lid).
    Uses the head's ``eyelid_*`` skin regions; empty dict without them.
    """
    ids = [
        np.asarray(head.regions[k])
        for k in head.regions
        if k.startswith("eyelid_") and len(head.regions[k])
    ]
    if not ids or not head.meshes["eyes"].n_vertices:
        return {}
    v = head.skin.vertices[np.concatenate(ids)]
    own = eye_owner(head.eye_centres, v)
    gap = np.linalg.norm(v - head.eye_centres[own], axis=1) - head.eye_radius
    return {"min": float(gap.min()), "median": float(np.median(gap))}
