"""Local surface patches, plane sections and profile concavities on a triangle mesh.

The geometry behind snapping a landmark to a feature
(:mod:`workbench.services.landmarks.snap`), kept apart as plain numerics:

* :class:`PatchIndex` finds the *patch* under a point: the vertices within a
  radius that are connected, through mesh edges inside that ball, to the
  vertex nearest the point (so a search cannot jump across a gap to the
  other side of a thin bone or to another bone);
* :func:`plane_section` gives the points where a patch's edges cross a plane
  (the exact profile of the surface in that plane, on the surface);
* :func:`depth_below_upper_hull` measures how deep each point of a 2-D
  profile lies below the line touching the profile on both sides;
* :meth:`PatchIndex.seen_from` (by rays) and :func:`front_profile` (in the
  plane) tell the outer profile from what lies behind it (sinus walls, the
  inner table of a CT bone).

Units: mm, any frame (the mesh's).  All functions are vectorised.
"""

from __future__ import annotations

import weakref
from functools import cached_property

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree

from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.core.raycast import RayCaster

#: rays of :meth:`PatchIndex.seen_from` start this far (mm) off their point
SEEN_OFFSET_MM = 0.2


class PatchIndex:
    """Per-mesh structures for patch queries, built on first use, then reused.

    Holds the mesh weakly (so a cache keyed by the mesh can let it go) and its
    vertex array strongly.

    Parameters
    ----------
    mesh : Mesh
        Surface in mm, any frame.
    """

    def __init__(self, mesh: Mesh):
        self._mesh = weakref.ref(mesh)
        self.vertices = mesh.vertices

    @property
    def mesh(self) -> Mesh:
        mesh = self._mesh()
        if mesh is None:
            raise RuntimeError("the mesh of this PatchIndex no longer exists")
        return mesh

    @cached_property
    def caster(self) -> RayCaster:
        """Ray caster over the mesh (:mod:`workbench.core.raycast`)."""
        return RayCaster(self.mesh)

    def seen_from(self, points: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """``(k,)`` bool: whether each surface point can be seen from far along the unit
        ``direction``, i.e. no part of the surface lies in front of it.

        A CT bone's midline section holds more than the outer profile: behind it lie
        inner walls (sinuses, the nasal floor, the inner table), which face forward too,
        and the deepest point of the whole section can be one of them.  A ray from each point
        (started :data:`SEEN_OFFSET_MM` off it, clear of its own triangles) that meets the
        surface marks the point hidden.  mm, the mesh's frame.
        """
        p = np.asarray(points, np.float64).reshape(-1, 3)
        if not len(p):
            return np.zeros(0, bool)
        d = np.broadcast_to(np.asarray(direction, np.float64), p.shape)
        return ~self.caster.first_hits(p + SEEN_OFFSET_MM * d, d).hit

    @cached_property
    def tree(self) -> cKDTree:
        """k-d tree over the vertices."""
        return cKDTree(self.vertices)

    @cached_property
    def adjacency(self) -> sparse.csr_matrix:
        """``(n, n)`` symmetric vertex adjacency through mesh edges."""
        e, n = self.mesh.edges_unique, len(self.vertices)
        ones = np.ones(2 * len(e), dtype=np.int8)
        ij = (np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]]))
        return sparse.csr_matrix((ones, ij), shape=(n, n))

    @cached_property
    def normals(self) -> np.ndarray:
        """``(n, 3)`` outward unit vertex normals (winding judged over the whole mesh)."""
        m = self.mesh
        centres = m.triangles.mean(axis=1)
        agree = np.einsum("ij,ij->i", m.face_cross, centres - centres.mean(axis=0)).sum()
        return vertex_normals(m) * (1.0 if agree >= 0 else -1.0)

    def warm(self) -> PatchIndex:
        """Build everything now (e.g. in a worker when a mesh is opened)."""
        _ = self.tree, self.adjacency, self.normals
        return self

    def patch(self, point: np.ndarray, radius_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """``(vertex ids (k,), local edges (e, 2))`` of the patch under ``point``.

        The vertices within ``radius_mm`` of ``point`` connected, through
        edges inside the ball, to the vertex nearest it (always included).
        Edges are pairs of positions in the returned ids.
        """
        _, nearest = self.tree.query(point)
        ball = np.union1d(
            np.asarray(self.tree.query_ball_point(point, radius_mm), np.int64), [nearest]
        )
        sub = self.adjacency[ball][:, ball]
        _, labels = connected_components(sub, directed=False)
        keep = labels == labels[np.searchsorted(ball, nearest)]
        edges = sparse.triu(sub[keep][:, keep], k=1).tocoo()
        return ball[keep], np.column_stack([edges.row, edges.col])


def plane_section(
    points: np.ndarray, normals: np.ndarray, edges: np.ndarray, signed_mm: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where ``edges`` cross a plane: ``(points (c, 3), interpolated normals (c, 3))``.

    ``signed_mm`` is each point's signed distance from the plane; edges whose
    ends have opposite signs are cut linearly, and points exactly on the
    plane are kept.  The result lies on the surface (on its edges) and on
    the plane.  Normals are interpolated, not renormalised.
    """
    a, b = edges[:, 0], edges[:, 1]
    cross = signed_mm[a] * signed_mm[b] < 0.0
    a, b = a[cross], b[cross]
    t = (signed_mm[a] / (signed_mm[a] - signed_mm[b]))[:, None]
    on = signed_mm == 0.0
    return (
        np.concatenate([points[a] + t * (points[b] - points[a]), points[on]]),
        np.concatenate([normals[a] + t * (normals[b] - normals[a]), normals[on]]),
    )


def depth_below_upper_hull(along: np.ndarray, height: np.ndarray) -> np.ndarray | None:
    """Depth of each point of a 2-D profile below the profile's upper convex hull.

    Parameters
    ----------
    along, height : (k,) float64
        Coordinate along the profile and height across it (mm).

    Returns
    -------
    (k,) float64 or None
        ``>= 0``; 0 on the hull, largest at the bottom of the deepest
        concavity (measured along ``height``).  None for fewer than three
        points or collinear ones.
    """
    try:
        hull = ConvexHull(np.column_stack([along, height]))
    except (QhullError, ValueError):
        return None
    eq = hull.equations  # n_along * a + n_height * h + offset <= 0 inside
    upper = eq[eq[:, 1] > 1e-9]  # hull edges facing up in 'height'
    if not len(upper):
        return None
    # height of each upper edge's line at every point's 'along'; the hull is their minimum
    h_line = -(np.outer(along, upper[:, 0]) + upper[:, 2]) / upper[:, 1]
    return np.maximum(h_line.min(axis=1) - height, 0.0)


def front_profile(
    along: np.ndarray, height: np.ndarray, window_mm: float = 0.75, tol_mm: float = 3.0
) -> np.ndarray:
    """Indices of the points of a 2-D profile not hidden by another: none lies within
    ``window_mm`` along the profile and more than ``tol_mm`` higher.

    The section of a CT bone through its midline holds the outer profile and, behind it,
    inner walls.  Rays (:meth:`PatchIndex.seen_from`) tell them apart where the outer
    wall is whole; a thin wall that the iso level left with holes lets some rays
    through, and this test, in the plane, holds those back.  The narrow window (it
    spans the ~1.5 mm between the points where a 100k-triangle skull's edges cross the
    midline) and the large step keep the bottom of a concavity whose sides rise less
    than 4 mm per mm, while a wall ~10 mm behind the outer one is hidden.  mm.
    """
    along = np.asarray(along, np.float64)
    height = np.asarray(height, np.float64)
    if not len(along):
        return np.zeros(0, np.int64)
    near = np.abs(along[:, None] - along[None, :]) <= window_mm
    hidden = (near & (height[None, :] > height[:, None] + tol_mm)).any(axis=1)
    return np.flatnonzero(~hidden)
