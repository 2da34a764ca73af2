"""A bounding-volume hierarchy over triangles, queried many points at a time.

Units: mm in the mesh's frame.

Layout: faces are sorted along a Morton (Z-order) curve of their centroids
and cut into leaves of ``leaf_size`` consecutive faces; the leaves are padded
to a power of two and paired level by level, so the tree is implicit (node
``i`` at one level has children ``2i`` and ``2i + 1`` one level down) and
every level is a pair of ``(n, 3)`` arrays of box corners.

Queries are vectorised breadth-first branch and bound: the set of
(query, node) pairs whose box lies within the query's current upper bound
is refined one level at a time, then leaves are opened nearest first.  This
is what makes closest-point queries far from the surface cheap, where a
k-d tree over centroids would need thousands of candidates.
"""

from __future__ import annotations

import numpy as np

from workbench.core.mesh import Mesh


def _morton_order(points: np.ndarray) -> np.ndarray:
    lo = points.min(axis=0)
    span = np.maximum(points.max(axis=0) - lo, 1e-300)
    q = np.clip(((points - lo) / span * 1023.0).astype(np.uint64), 0, 1023)
    code = np.zeros(len(points), np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(code, kind="stable")


def _box_distance(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    d = np.maximum(np.maximum(lo - p, p - hi), 0.0)
    return np.sqrt(np.einsum("ij,ij->i", d, d))


class TriangleBVH:
    """Implicit AABB tree over the faces of a mesh."""

    def __init__(self, mesh: Mesh, leaf_size: int = 8):
        tri = mesh.triangles
        m = len(tri)
        self.leaf_size = leaf_size
        self.order = _morton_order(tri.mean(axis=1))
        sorted_tri = tri[self.order]
        n_leaves = -(-m // leaf_size)
        padded = 1 << max(0, int(np.ceil(np.log2(max(n_leaves, 1)))))
        starts = np.arange(n_leaves) * leaf_size
        lo = np.full((padded, 3), np.inf)
        hi = np.full((padded, 3), -np.inf)
        lo[:n_leaves] = np.minimum.reduceat(sorted_tri.min(axis=1), starts, axis=0)
        hi[:n_leaves] = np.maximum.reduceat(sorted_tri.max(axis=1), starts, axis=0)
        levels = [(lo, hi)]
        while len(lo) > 1:
            lo = np.minimum(lo[0::2], lo[1::2])
            hi = np.maximum(hi[0::2], hi[1::2])
            levels.append((lo, hi))
        self.levels = levels[::-1]  # root first
        self.n_faces = m
        self.n_leaves = n_leaves

    def leaf_faces(self, leaf: np.ndarray) -> np.ndarray:
        """``(k, leaf_size)`` face ids of leaves (``-1`` past the last face)."""
        idx = leaf[:, None] * self.leaf_size + np.arange(self.leaf_size)[None, :]
        valid = idx < self.n_faces
        return np.where(valid, self.order[np.minimum(idx, self.n_faces - 1)], -1)

    def candidate_leaves(self, points: np.ndarray, bound: np.ndarray) -> tuple[np.ndarray, ...]:
        """Leaves whose box lies within ``bound`` of each point.

        Returns ``(query_index, leaf_index, lower_bound)`` sorted by query,
        then by lower bound (nearest leaf first).
        """
        q = np.arange(len(points))
        node = np.zeros(len(points), np.int64)
        for depth, (lo, hi) in enumerate(self.levels):
            lb = _box_distance(points[q], lo[node], hi[node])
            keep = lb <= bound[q]
            q, node, lb = q[keep], node[keep], lb[keep]
            if depth + 1 < len(self.levels):
                q = np.repeat(q, 2)
                node = (np.repeat(node, 2) * 2) + np.tile([0, 1], len(node))
        order = np.lexsort((lb, q))
        return q[order], node[order], lb[order]
