"""Pure geometry for painting muscle grids on the template skin (numpy only).

Helpers used by :mod:`workbench.services.templates.muscles`:

* :func:`linear_rows` -- guide points of a linear muscle, row by row from
  the fixed end to the free end;
* :func:`mirror_surface_points` -- exact left/right mirror of points stored
  as (face, barycentric) on a mesh that is symmetric under x -> -x;
* :func:`polar_radius` -- radius of a closed 2-D loop seen from its centre,
  for rings drawn at an offset around an opening.

Units: mm, head frame (x = subject's left, y up, z forward).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

MIRROR = np.array([-1.0, 1.0, 1.0])


def unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def linear_rows(
    fixed: np.ndarray,
    free: np.ndarray,
    row_lengths: tuple[int, ...],
    widths: tuple[float, float],
    outward,
) -> list[np.ndarray]:
    """Guide points of a linear muscle: rows from ``fixed`` (t = 0) to ``free`` (t = 1).

    Row i is centred on the straight line between the end centres and
    spreads its points evenly over a width interpolated between
    ``widths = (w_fixed, w_free)``, across the muscle direction and the
    outward direction ``outward(point) -> (3,)`` there.
    """
    fixed, free = np.asarray(fixed, float), np.asarray(free, float)
    n = len(row_lengths)
    rows = []
    for i, count in enumerate(row_lengths):
        t = i / (n - 1) if n > 1 else 0.0
        centre = fixed + t * (free - fixed)
        across = unit(np.cross(free - fixed, outward(centre)))
        w = widths[0] + t * (widths[1] - widths[0])
        offs = np.linspace(-w / 2, w / 2, count) if count > 1 else np.zeros(1)
        rows.append(centre[None] + offs[:, None] * across[None])
    return rows


def polar_radius(loop_xy: np.ndarray, centre: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Distance from ``centre`` to a closed 2-D loop along each direction in ``angles`` (rad)."""
    rel = np.asarray(loop_xy, float) - np.asarray(centre, float)[None]
    phi = np.arctan2(rel[:, 1], rel[:, 0])
    r = np.linalg.norm(rel, axis=1)
    order = np.argsort(phi)
    return np.interp(angles, phi[order], r[order], period=2 * np.pi)


def mirror_maps(
    vertices: np.ndarray, faces: np.ndarray, tol: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    """Vertex and face partners under x -> -x: ``(vertex_partner, face_partner)``.

    ``face_partner[f]`` is the face whose corners are the partners of f's
    corners (in some order); raises if the mesh is not symmetric.
    """
    dist, vp = cKDTree(np.asarray(vertices) * MIRROR).query(vertices)
    if dist.max() > tol:
        raise ValueError(f"mesh is not mirror symmetric ({dist.max():.3g} mm)")
    key = {tuple(sorted(f)): i for i, f in enumerate(np.asarray(faces).tolist())}
    fp = np.array([key[tuple(sorted(vp[f]))] for f in faces], dtype=np.int64)
    return vp, fp


def mirror_surface_points(
    faces: np.ndarray,
    vertex_partner: np.ndarray,
    face_partner: np.ndarray,
    face_ids: np.ndarray,
    barycentric: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Mirror (face, barycentric) points: same weights on the partner corners."""
    face_ids = np.asarray(face_ids, dtype=np.int64)
    new_f = face_partner[face_ids]
    new_b = np.zeros_like(np.asarray(barycentric, float))
    src_partners = vertex_partner[faces[face_ids]]  # partner of each source corner
    dst = faces[new_f]
    for k in range(3):
        match = dst == src_partners[:, k : k + 1]  # where that corner sits in the new face
        new_b += match * barycentric[:, k : k + 1]
    return new_f, new_b
