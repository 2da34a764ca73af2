"""Surface normals: per vertex, and averaged over a radius.

Units: positions and radii in mm; normals are unit vectors in the mesh frame.

Scanned or CT-extracted skull surfaces are bumpy at the millimetre scale, so
the normal of a single triangle (or vertex) is "too local" to orient a
tissue-depth dowel (Kähler 2003, §8.6.8).  :func:`normals_within_radius`
averages area-weighted face normals over a ball around each query point,
with a smooth (Epanechnikov-type) fall-off so that the result changes
continuously as the point slides over the surface.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

if TYPE_CHECKING:  # the mesh computes its own normals: no import back at run time
    from workbench.core.mesh import Mesh


def _normalise(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, v / np.where(n > 0, n, 1.0), 0.0)


def vertex_normals(mesh: Mesh) -> np.ndarray:
    """``(n, 3)`` area-weighted vertex normals (unit; zero for isolated vertices), a
    writable copy of :attr:`workbench.core.mesh.Mesh.vertex_normals`."""
    return np.array(mesh.vertex_normals)


def angle_weighted_vertex_normals(mesh: Mesh) -> np.ndarray:
    """``(n, 3)`` vertex normals weighted by the corner angle of each face.

    These are the pseudo-normals of Bærentzen & Aanæs (2005) that make the
    sign of a closest-point distance exact on closed meshes.
    """
    return _normalise(angle_weighted_sums(mesh)[0])


def angle_weighted_sums(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex: the sum of its faces' normals times their corner angle ``(n, 3)``, and the
    sum of those corner angles ``(n,)`` (radians)."""
    t = mesh.triangles
    normals = mesh.face_normals
    acc = np.zeros((mesh.n_vertices, 3))
    total = np.zeros(mesh.n_vertices)
    for corner in range(3):
        a = t[:, (corner + 1) % 3] - t[:, corner]
        b = t[:, (corner + 2) % 3] - t[:, corner]
        cos = np.einsum("ij,ij->i", a, b) / np.maximum(
            np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300
        )
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        ids = mesh.faces[:, corner]
        total += np.bincount(ids, weights=angle, minlength=mesh.n_vertices)
        weighted = normals * angle[:, None]
        for axis in range(3):
            acc[:, axis] += np.bincount(ids, weights=weighted[:, axis], minlength=mesh.n_vertices)
    return acc, total


def normals_within_radius(
    mesh: Mesh,
    points: np.ndarray,
    radius_mm: float,
    *,
    tree: cKDTree | None = None,
    fallback: np.ndarray | None = None,
) -> np.ndarray:
    """Surface normal at ``points`` averaged over a ball of ``radius_mm``.

    Parameters
    ----------
    mesh : Mesh
        Surface in mm with outward winding.
    points : (k, 3) float64
        Query points on or near the surface (mm).
    radius_mm : float
        Averaging radius; faces whose centroid lies within it contribute
        ``area x (1 - (d / r)²)``.
    tree : cKDTree, optional
        Prebuilt tree over ``mesh`` face centroids (reuse it for many calls).
    fallback : (k, 3), optional
        Normals to use where no face lies within the radius (default: the
        normal of the nearest face).

    Returns
    -------
    (k, 3) float64 unit vectors.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if radius_mm <= 0:
        raise ValueError("radius_mm must be positive")
    centroids = mesh.triangles.mean(axis=1)
    if tree is None:
        tree = cKDTree(centroids)
    neighbours = tree.query_ball_point(pts, r=radius_mm)
    counts = np.fromiter((len(n) for n in neighbours), dtype=np.int64, count=len(pts))
    result = np.zeros((len(pts), 3))
    if counts.sum():
        rows = np.repeat(np.arange(len(pts)), counts)
        cols = np.concatenate([np.asarray(n, dtype=np.int64) for n in neighbours if len(n)])
        d = np.linalg.norm(centroids[cols] - pts[rows], axis=1) / radius_mm
        weights = mesh.face_areas[cols] * np.clip(1.0 - d**2, 0.0, None)
        w = sparse.csr_matrix((weights, (rows, cols)), shape=(len(pts), mesh.n_faces))
        result = np.asarray(w @ mesh.face_normals)
    result = _normalise(result)
    empty = ~np.linalg.norm(result, axis=1).astype(bool)
    if empty.any():
        if fallback is None:
            _, nearest = tree.query(pts[empty])
            result[empty] = mesh.face_normals[nearest]
        else:
            result[empty] = _normalise(np.asarray(fallback, float).reshape(-1, 3)[empty])
    return result
