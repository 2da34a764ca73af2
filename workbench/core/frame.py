"""The head frame and Frankfort Horizontal alignment.

The head frame
--------------
Every module works in one frame, in millimetres:

* **x** runs across the head toward the **subject's left**; x = 0 is the
  midsagittal plane;
* **y** points **up**, perpendicular to the Frankfort Horizontal (FH) plane;
* **z** points **forward**, toward the face;
* the origin lies on the midsagittal plane, in the FH plane, on the
  vertical line through the midpoint of the two porions.

(x, y, z) is right-handed.  In anatomical terms it is (Left, Superior,
Anterior); RAS coordinates map to it as ``x = -R, y = S, z = A``.  Viewed
from the front, the subject's left is on the viewer's right, so +x points to
the right of the screen in a frontal view.

FH is the plane through the left and right porion (po, upper margin of the
external auditory meatus) and the orbitale (or, lowest point of the
infraorbital margin); with both orbitales the plane is fitted through all four
points in the least-squares sense.

Results handed back to a user are mapped back into the user's input frame
with :meth:`HeadFrame.to_input`; only internal computation happens in the
head frame.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

RAS_TO_HEAD = np.array(
    [[-1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
"""4x4 rotation taking RAS coordinates (x right, y anterior, z superior) to head axes."""


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n == 0 or not np.isfinite(n):
        raise ValueError("cannot normalise a zero or non-finite vector")
    return v / n


def apply_transform(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4x4 homogeneous transform to ``(n, 3)`` points."""
    m = np.asarray(matrix, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    return p @ m[:3, :3].T + m[:3, 3]


@dataclass(frozen=True)
class HeadFrame:
    """A rigid map from the user's input frame into the head frame.

    Attributes
    ----------
    input_to_head : (4, 4) float64
        Proper rigid transform (rotation + translation, det = +1, no scale).
    mirrored_input : bool
        True when the landmarks' left/right labels imply a mirrored input
        (e.g. a mesh exported with one axis flipped).  The frame is still a
        rotation; callers decide whether to refuse or to flag.
    fh_residual_mm : float
        RMS distance of the four FH landmarks from the fitted plane (0 with
        three landmarks).  Large values point at a misplaced landmark.
    """

    input_to_head: np.ndarray
    mirrored_input: bool = False
    fh_residual_mm: float = 0.0

    @property
    def head_to_input(self) -> np.ndarray:
        r = self.input_to_head[:3, :3]
        inv = np.eye(4)
        inv[:3, :3] = r.T
        inv[:3, 3] = -r.T @ self.input_to_head[:3, 3]
        return inv

    def to_head(self, points: np.ndarray) -> np.ndarray:
        return apply_transform(self.input_to_head, points)

    def to_input(self, points: np.ndarray) -> np.ndarray:
        return apply_transform(self.head_to_input, points)


def _fit_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    centre = points.mean(axis=0)
    _, s, vt = np.linalg.svd(points - centre)
    normal = vt[-1]
    rms = float(s[-1] / np.sqrt(len(points))) if len(points) > 3 else 0.0
    return centre, normal, rms


def frankfort_frame(
    po_l: np.ndarray,
    po_r: np.ndarray,
    or_l: np.ndarray,
    or_r: np.ndarray | None = None,
    midline: Iterable[np.ndarray] | None = None,
    above: Iterable[np.ndarray] | None = None,
    below: Iterable[np.ndarray] | None = None,
) -> HeadFrame:
    """Head frame from porions, orbitale(s) and optionally midline landmarks.

    Parameters
    ----------
    po_l, po_r : (3,) float64
        Left and right porion in the input frame (mm).
    or_l : (3,) float64
        Left orbitale (the classic FH uses left orbitale with both porions).
    or_r : (3,) float64, optional
        Right orbitale; when given, FH is the least-squares plane of all four.
    midline : iterable of (3,), optional
        Midline landmarks (e.g. nasion, prosthion, basion, opisthocranion).
        With two or more, the midsagittal plane is fitted through them
        (constrained perpendicular to FH); otherwise it is the plane
        perpendicular to the porion axis through the porion midpoint.
    above, below : iterable of (3,), optional
        Landmarks known to lie above FH (e.g. nasion, glabella, bregma) or
        below it (e.g. prosthion, menton).  With left/right taken at face
        value, a mirrored input puts the frame upside down; these points
        detect that and set ``mirrored_input``.

    Returns
    -------
    HeadFrame
    """
    po_l, po_r, or_l = (np.asarray(p, dtype=np.float64).reshape(3) for p in (po_l, po_r, or_l))
    fh_points = [po_l, po_r, or_l]
    if or_r is not None:
        fh_points.append(np.asarray(or_r, dtype=np.float64).reshape(3))
    fh = np.stack(fh_points)
    if not np.isfinite(fh).all():
        raise ValueError("Frankfort landmarks must all be defined")
    _, up, rms = _fit_plane(fh)
    lateral = po_l - po_r
    if np.linalg.norm(lateral) < 1e-6:
        raise ValueError("left and right porion coincide; cannot define the head frame")
    orbit_mid = fh[2:].mean(axis=0)
    po_mid = 0.5 * (po_l + po_r)
    forward = orbit_mid - po_mid
    # x toward the subject's left, projected into FH
    x_axis = _unit(lateral - np.dot(lateral, up) * up)
    # Orient 'up' so that (x, up, forward) is right-handed with forward
    # pointing to the orbitales: up = forward × x.
    z_guess = forward - np.dot(forward, up) * up - np.dot(forward, x_axis) * x_axis
    z_guess = _unit(z_guess)
    y_axis = _unit(np.cross(z_guess, x_axis))
    # The plane fit gives 'up' with an arbitrary sign; handedness fixes it
    # (y = z x x).  If the input is mirrored but labelled anatomically, that
    # makes the frame upside down, which the above/below checks reveal.
    mirrored = _looks_upside_down(fh.mean(axis=0), y_axis, above, below)
    midline_pts = (
        np.asarray(list(midline), dtype=np.float64).reshape(-1, 3) if midline is not None else None
    )
    if midline_pts is not None and len(midline_pts) >= 2:
        x_axis = _midsagittal_normal(midline_pts, y_axis, x_axis)
        z_axis = _unit(np.cross(x_axis, y_axis))
        origin_x_point = midline_pts.mean(axis=0)
    else:
        z_axis = _unit(np.cross(x_axis, y_axis))
        origin_x_point = po_mid
    rot = np.stack([x_axis, y_axis, z_axis])  # rows: head axes in input coords
    if np.linalg.det(rot) < 0:  # pragma: no cover - guarded by construction
        raise ValueError("internal error: head frame is not right-handed")
    # origin: x from the midsagittal plane, y from FH, z from the porion midpoint
    origin = (
        x_axis * np.dot(origin_x_point, x_axis)
        + y_axis * np.dot(fh.mean(axis=0), y_axis)
        + z_axis * np.dot(po_mid, z_axis)
    )
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = -rot @ origin
    return HeadFrame(m, mirrored_input=mirrored, fh_residual_mm=rms)


def _midsagittal_normal(midline: np.ndarray, up: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """Unit normal of the plane through ``midline`` points that contains ``up``."""
    centred = midline - midline.mean(axis=0)
    # the plane contains 'up'; its normal is perpendicular to up: search in
    # the 2-D space orthogonal to up for the direction of least spread
    basis_a = _unit(x_hint - np.dot(x_hint, up) * up)
    basis_b = np.cross(up, basis_a)
    coords = np.stack([centred @ basis_a, centred @ basis_b], axis=1)
    _, _, vt = np.linalg.svd(coords, full_matrices=False)
    n2 = vt[-1]
    normal = _unit(n2[0] * basis_a + n2[1] * basis_b)
    return normal if np.dot(normal, x_hint) > 0 else -normal


def _looks_upside_down(
    fh_centre: np.ndarray,
    y_axis: np.ndarray,
    above: Iterable[np.ndarray] | None,
    below: Iterable[np.ndarray] | None,
) -> bool:
    votes = 0
    for pts, sign in ((above, 1.0), (below, -1.0)):
        for p in () if pts is None else pts:
            h = float(np.dot(np.asarray(p, dtype=np.float64) - fh_centre, y_axis))
            votes += 1 if sign * h < 0 else -1
    return votes > 0
