"""Points tied to a skin surface, so they follow the skin when it deforms.

A point near the skin is stored by the triangle it lies over, its
barycentric coordinates there and its offset from that surface point in a
frame built on the surface (the interpolated vertex normal and a tangent
along the triangle's first edge).  :meth:`ShellPoints.evaluate` rebuilds the
points on any skin with the same triangles: the reference head, a fitted
face, a build variant, an aged head or one frame of an animation.  On the
skin they were tied to the points come back exactly; on a deformed skin they
move with the surface under them, keep their height above it in mm and turn
with its normal.

Units: millimetres, in whatever frame the skin vertices are given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def vertex_normals_of(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """``(n, 3)`` unit area-weighted vertex normals of a skin given as arrays."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    summed = np.zeros_like(v)
    for k in range(3):
        np.add.at(summed, f[:, k], cross)
    return _unit(summed)


def surface_frames(
    vertices: np.ndarray,
    faces: np.ndarray,
    face_ids: np.ndarray,
    barycentric: np.ndarray,
    normals: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Surface points ``(k, 3)`` and frames ``(k, 3, 3)`` (rows: tangent, bitangent, normal).

    The normal is the barycentric blend of the vertex normals, so it turns
    smoothly from one triangle to the next; the tangent is the triangle's
    first edge made perpendicular to it.
    """
    v = np.asarray(vertices, float)
    tri = np.asarray(faces, np.int64)[np.asarray(face_ids, np.int64)]
    b = np.asarray(barycentric, float)
    corners = v[tri]  # (k, 3, 3)
    base = np.einsum("kj,kjd->kd", b, corners)
    vn = vertex_normals_of(v, faces) if normals is None else np.asarray(normals, float)
    n = _unit(np.einsum("kj,kjd->kd", b, vn[tri]))
    edge = corners[:, 1] - corners[:, 0]
    t = _unit(edge - np.einsum("kd,kd->k", edge, n)[:, None] * n)
    s = np.cross(n, t)
    return base, np.stack([t, s, n], axis=1)


@dataclass(frozen=True)
class ShellPoints:
    """Points tied to a skin (see the module notes).

    Attributes
    ----------
    face_ids : (k,) int
        Triangle of the skin under each point.
    barycentric : (k, 3)
        Where in that triangle.
    local : (k, 3)
        The offset from the surface point in its frame (tangent, bitangent,
        normal), mm; ``local[:, 2]`` is the height above the skin.
    """

    face_ids: np.ndarray
    barycentric: np.ndarray
    local: np.ndarray

    def __len__(self) -> int:
        return len(self.face_ids)

    @property
    def height(self) -> np.ndarray:
        """``(k,)`` height above the skin along its normal, mm."""
        return self.local[:, 2]

    def subset(self, rows: np.ndarray) -> ShellPoints:
        """The points ``rows`` only."""
        return ShellPoints(self.face_ids[rows], self.barycentric[rows], self.local[rows])

    @staticmethod
    def attach(skin: Mesh, points: np.ndarray) -> ShellPoints:
        """Tie ``points`` ``(k, 3)`` mm to ``skin`` (closest triangle, spatial index)."""
        pts = np.asarray(points, float).reshape(-1, 3)
        found = MeshIndex.shared(skin).closest_points(pts)
        base, frame = surface_frames(
            skin.vertices, skin.faces, found.face_ids, found.barycentric, skin.vertex_normals
        )
        local = np.einsum("kij,kj->ki", frame, pts - base)
        return ShellPoints(
            np.asarray(found.face_ids, np.int64), np.asarray(found.barycentric, float), local
        )

    def evaluate(
        self, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The points on the skin ``vertices`` ``(n, 3)`` mm (same ``faces`` as when tied)
        and the skin normal under each, both ``(k, 3)``."""
        base, frame = surface_frames(vertices, faces, self.face_ids, self.barycentric, normals)
        return base + np.einsum("kij,ki->kj", frame, self.local), frame[:, 2]


__all__ = ["ShellPoints", "surface_frames", "vertex_normals_of"]
