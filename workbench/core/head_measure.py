"""Tape measurements on a head mesh: the occipitofrontal (head) circumference.

Units mm.  The head circumference of growth charts (WHO 2006, UK90) is
taken with a tape over the most prominent point of the forehead (glabella)
and the most posterior point of the occiput (opisthocranion), the tape lying
level across both sides.  On the mesh: the section of the skin by the plane
through glabella and opisthocranion that is perpendicular to the
midsagittal plane (it contains the left-right axis), and the tape's length
is the perimeter of that section's convex hull in the plane — a tape bridges
concavities rather than following them (hair, the temporal hollows).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from workbench.core.mesh import Mesh


def plane_section_points(mesh: Mesh, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Points where ``mesh``'s edges cross the plane (point, normal); (k, 3) mm."""
    v = mesh.vertices
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    side = (v - np.asarray(point, float)) @ n
    edges = mesh.edges_unique
    sa, sb = side[edges[:, 0]], side[edges[:, 1]]
    cross = (sa * sb < 0) | ((sa == 0) & (sb != 0))
    e = edges[cross]
    t = sa[cross] / (sa[cross] - sb[cross])
    return v[e[:, 0]] + t[:, None] * (v[e[:, 1]] - v[e[:, 0]])


def head_circumference_mm(
    skin: Mesh, glabella: np.ndarray, opisthocranion: np.ndarray, lateral=(1.0, 0.0, 0.0)
) -> float:
    """Occipitofrontal circumference of ``skin`` (mm) through the two landmarks.

    ``lateral`` is the subject's left-right axis (x in the head frame).
    Returns NaN when the plane does not cut a closed head section (a face
    scan without the back of the head).
    """
    g = np.asarray(glabella, float)
    op = np.asarray(opisthocranion, float)
    along = g - op
    normal = np.cross(along, np.asarray(lateral, float))
    if np.linalg.norm(normal) < 1e-9:
        return float("nan")
    pts = plane_section_points(skin, op, normal)
    return section_perimeter(pts, g, op, lateral)


def head_section(
    skin: Mesh, glabella: np.ndarray, opisthocranion: np.ndarray, lateral=(1.0, 0.0, 0.0)
) -> np.ndarray:
    """The skin's section points through glabella and opisthocranion (mm; see the module)."""
    g = np.asarray(glabella, float)
    op = np.asarray(opisthocranion, float)
    normal = np.cross(g - op, np.asarray(lateral, float))
    if np.linalg.norm(normal) < 1e-9:
        return np.zeros((0, 3))
    return plane_section_points(skin, op, normal)


def section_perimeter(
    pts: np.ndarray, glabella: np.ndarray, opisthocranion: np.ndarray, lateral=(1.0, 0.0, 0.0)
) -> float:
    """Tape length around section points ``pts`` (mm): their convex hull's perimeter in the
    plane through glabella and opisthocranion that contains the lateral axis (NaN if the
    points do not go round a head)."""
    g = np.asarray(glabella, float)
    op = np.asarray(opisthocranion, float)
    along = g - op
    normal = np.cross(along, np.asarray(lateral, float))
    if len(pts) < 8 or np.linalg.norm(normal) < 1e-9:
        return float("nan")
    u = along / np.linalg.norm(along)
    w = np.cross(normal / np.linalg.norm(normal), u)
    flat = np.column_stack([(pts - op) @ u, (pts - op) @ w])
    # keep the loop around the head: section points within the head's front-back span
    span = np.linalg.norm(along)
    keep = (flat[:, 0] > -0.1 * span) & (flat[:, 0] < 1.1 * span)
    flat = flat[keep]
    if len(flat) < 8 or np.ptp(flat[:, 1]) < 0.3 * span:
        return float("nan")
    try:
        hull = ConvexHull(flat)
    except QhullError:
        return float("nan")
    # for a 2-D hull, qhull's "area" is the perimeter
    return float(hull.area)
