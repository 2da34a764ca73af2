"""Leaves of triangles under a bounding-box tree, for exact closest-point search.

Units: mm in the mesh's frame.

Layout
------
Face centroids are split at the median of their widest axis, recursively,
until every leaf holds about eight faces: a balanced binary tree stored
implicitly in heap order (node ``h`` has children ``2h`` and ``2h + 1``, the
root is 1, leaf ``i`` is node ``n_leaves + i``), whose leaves are compact
patches of the surface.

Bounds
------
Every node has an axis-aligned box (exact: merged bottom-up from the
triangles).  Leaves also have an *oriented* box along the principal axes of
their corners, which is much thinner for the flat patches a surface is made
of; a leaf is within reach of a query only if both of its boxes are.

:meth:`LeafTree.descend` finds, breadth-first for many queries at once, every
leaf within a given distance; the box tests run in single precision with the
bound widened to cover rounding (never too few leaves, at worst a few more).
:meth:`LeafTree.leaf_distances` then measures the exact point-triangle
distances, with every face stored in a local 2-D frame (corner ``a`` at the
origin, the longest edge along x, the normal as z) so that it is a fixed
sequence of array operations with no branches and no cancellation near the
surface.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from workbench.core import bvh_build
from workbench.core.mesh import Mesh

_COLUMNS = 19  # a(3) u(3) v(3) n(3) bx cx cy ex iac ibc ylo
_CHUNK_LEAVES = 1024  # leaves per exact-distance pass: keeps temporaries in cache


def split_leaves(points: np.ndarray, target_leaf: int = 8) -> np.ndarray:
    """``(2**depth, leaf_size)`` point indices (``-1`` = padding) of median-split leaves.

    Leaf ``i`` and ``i ^ 1`` are siblings: the leaves are the bottom level of
    an implicit complete binary tree.  The leaf size is chosen near
    ``target_leaf`` so that little padding is needed; padding collects in
    the last leaves (some of which may be empty).
    """
    n = len(points)
    depth = max(0, int(round(np.log2(max(1.0, n / target_leaf)))))
    leaf_size = max(1, -(-n // (1 << depth)))
    slots = leaf_size << depth
    perm = np.full(slots, -1, np.int64)
    perm[:n] = np.arange(n)
    coords = np.full((3, slots), np.inf)  # padding sorts last
    coords[:, :n] = points.T
    for level in range(depth):
        rows = 1 << level
        seg = perm.reshape(rows, -1)
        c = coords.reshape(3, rows, -1)
        finite = seg >= 0
        lo = c.min(axis=2)
        hi = np.where(finite, c, -np.inf).max(axis=2)
        axis = np.argmax(hi - lo, axis=0)  # widest extent of each group
        key = c[axis, np.arange(rows)]
        order = np.argpartition(key, seg.shape[1] // 2 - 1, axis=1)
        perm = np.take_along_axis(seg, order, axis=1).ravel()
        coords = np.take_along_axis(c, order[None], axis=2).reshape(3, -1)
    return perm.reshape(1 << depth, leaf_size)


def _split_compiled(points: np.ndarray, target_leaf: int = 8) -> np.ndarray:
    """:func:`split_leaves` by the compiled loops of :mod:`workbench.core.bvh_build`."""
    n = len(points)
    depth = max(0, int(round(np.log2(max(1.0, n / target_leaf)))))
    leaf_size = max(1, -(-n // (1 << depth)))
    perm = np.full(leaf_size << depth, -1, np.int64)
    perm[:n] = np.arange(n)
    assert bvh_build.split_jit is not None  # the caller checked
    bvh_build.split_jit(np.ascontiguousarray(points, dtype=np.float64), depth, leaf_size, perm)
    return perm.reshape(1 << depth, leaf_size)


def _face_frames(tri: np.ndarray) -> np.ndarray:
    """``(_COLUMNS, m)`` per-face local frame used by :meth:`LeafTree.leaf_distances`."""
    m = len(tri)
    edge_len = np.stack(
        [np.linalg.norm(tri[:, (i + 1) % 3] - tri[:, i], axis=1) for i in range(3)], axis=1
    )
    first = edge_len.argmax(axis=1)  # cyclic relabel: longest edge is a -> b
    idx = (first[:, None] + np.arange(3)[None, :]) % 3
    t = np.take_along_axis(tri, idx[..., None], axis=1)
    a, e0, e1 = t[:, 0], t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    len0 = np.linalg.norm(e0, axis=1)
    cross = np.cross(e0, e1)
    cross_len = np.linalg.norm(cross, axis=1)
    good = cross_len > 1e-14 * np.maximum(len0, 1e-300) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(len0[:, None] > 0, e0 / len0[:, None], [1.0, 0.0, 0.0])
        n = np.where(good[:, None], cross / cross_len[:, None], 0.0)
    # degenerate faces: any unit normal perpendicular to u
    helper = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    alt = np.cross(u, helper)
    alt /= np.linalg.norm(alt, axis=1, keepdims=True)
    n = np.where(good[:, None], n, alt)
    v = np.cross(n, u)
    bx = len0
    cx = np.einsum("ij,ij->i", e1, u)
    cy = np.where(good, np.einsum("ij,ij->i", e1, v), 0.0)
    ex = cx - bx
    # edges shorter than 1e-15 of the longest count as points (t = 0)
    tiny = np.maximum(1e-30 * bx * bx, 1e-300)
    lac, lbc = cx * cx + cy * cy, ex * ex + cy * cy
    iac = np.where(lac > tiny, 1.0 / np.maximum(lac, tiny), 0.0)
    ibc = np.where(lbc > tiny, 1.0 / np.maximum(lbc, tiny), 0.0)
    ylo = np.where(good, 0.0, np.inf)  # degenerate faces have no interior
    table = np.empty((_COLUMNS, m))
    table[0:3], table[3:6], table[6:9], table[9:12] = a.T, u.T, v.T, n.T
    table[12:] = bx, cx, cy, ex, iac, ibc, ylo
    return table


def oriented_boxes(points: np.ndarray) -> np.ndarray:
    """Oriented bounding boxes ``(k, 15)`` of point groups ``points`` ``(k, c, 3)``.

    Rows: centre (3), three orthonormal axes (principal axes of the group,
    largest spread first, 9) and the half extents along them (3), with a
    small margin for rounding.
    """
    mean = points.mean(axis=1)
    rel = points - mean[:, None]
    rel_t = np.swapaxes(rel, 1, 2)
    _, vec = np.linalg.eigh(np.matmul(rel_t, rel))
    axes = np.swapaxes(vec, 1, 2)[:, ::-1]
    local = np.matmul(axes, rel_t)  # (k, 3, c)
    lo, hi = local.min(axis=2), local.max(axis=2)
    centre = mean + np.matmul((0.5 * (lo + hi))[:, None, :], axes)[:, 0]
    size = np.maximum(np.abs(lo), np.abs(hi)).max(axis=1)
    margin = 1e-9 * size + 1e-12 * (np.abs(mean).max(axis=1) + 1.0)
    half = 0.5 * (hi - lo) + margin[:, None]
    return np.concatenate([centre, axes.reshape(-1, 9), half], axis=1)


def box_bound(p: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Squared distance from points ``p`` ``(m, 3)`` to oriented boxes ``box`` ``(m, 15)``."""
    rx, ry, rz = p[:, 0] - box[:, 0], p[:, 1] - box[:, 1], p[:, 2] - box[:, 2]
    total: np.ndarray | None = None
    for axis in range(3):
        col = 3 + 3 * axis
        x = rx * box[:, col]
        x += ry * box[:, col + 1]
        x += rz * box[:, col + 2]
        np.abs(x, out=x)
        x -= box[:, 12 + axis]
        np.maximum(x, 0.0, out=x)
        x *= x
        total = x if total is None else np.add(total, x, out=total)
    assert total is not None  # three axes summed
    return total


def aabb_bound(p: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Squared distance from points ``p`` ``(m, 3)`` to axis-aligned boxes ``(m, 6)``.

    Box rows: centre (3), half extents (3).
    """
    total: np.ndarray | None = None
    for axis in range(3):
        x = p[:, axis] - box[:, axis]
        np.abs(x, out=x)
        x -= box[:, 3 + axis]
        np.maximum(x, 0.0, out=x)
        x *= x
        total = x if total is None else np.add(total, x, out=total)
    assert total is not None  # three axes summed
    return total


def _segment_dist2(
    x: np.ndarray, y: np.ndarray, ux: np.ndarray, uy: np.ndarray, inv_len2: np.ndarray
) -> np.ndarray:
    """Squared distance in the triangle plane from ``(x, y)`` to the segment 0 → ``(ux, uy)``."""
    s = x * ux
    s += y * uy
    s *= inv_len2
    np.clip(s, 0.0, 1.0, out=s)
    dx = x - s * ux
    dy = y - s * uy
    dx *= dx
    dy *= dy
    dx += dy
    return dx


class LeafTree:
    """Median-split leaves of a mesh's faces under an implicit tree of boxes.

    Attributes
    ----------
    leaf_faces : (n_leaves, leaf_size) int64
        Face ids per leaf (padding repeats a face of the same leaf).
    centre_tree, centre_leaf
        k-d tree over the box centres of the non-empty leaves, used to find
        a first, nearby leaf for each query.
    origin, aabb32, obb32, size
        Boxes in single precision relative to ``origin`` (the mesh centre):
        ``aabb32`` ``(2 n_leaves, 6)`` (centre, half extents) in heap order,
        ``obb32`` ``(n_leaves, 15)`` for the leaves; ``size`` is the largest
        extent of the mesh.
    aabb_lo, aabb_hi : (2 n_leaves, 3)
        The axis-aligned boxes in double precision (slightly widened), for
        ray casting.
    """

    def __init__(self, mesh: Mesh, target_leaf: int = 8, *, compiled: bool = True):
        tri = mesh.triangles
        use_jit = compiled and bvh_build.leaves_jit is not None
        slots = (_split_compiled if use_jit else split_leaves)(tri.mean(axis=1), target_leaf)
        real = slots >= 0
        faces = np.where(real, slots, slots.ravel()[real.ravel()][-1])
        self.leaf_faces = faces
        self.n_leaves, self.leaf_size = n, size = faces.shape
        self.depth = int(np.log2(n))
        lo, hi = mesh.bounds
        self.origin = 0.5 * (lo + hi)
        self.size = float(np.abs(hi - lo).max()) + 1e-300
        # empty leaves (all padding) hold the filler face: harmless duplicates
        box_lo, box_hi = np.zeros((2 * n, 3)), np.zeros((2 * n, 3))
        if use_jit:
            self.table = np.empty((_COLUMNS, n, size))  # (C, leaves, L)
            obb = np.empty((n, 15))
            leaf_lo, leaf_hi = np.empty((n, 3)), np.empty((n, 3))
            assert bvh_build.leaves_jit is not None  # use_jit
            bvh_build.leaves_jit(
                np.ascontiguousarray(tri), faces, self.origin, self.table, obb, leaf_lo, leaf_hi
            )
            self.obb32 = obb.astype(np.float32)
            box_lo[n:], box_hi[n:] = leaf_lo, leaf_hi
        else:
            self.table = np.ascontiguousarray(_face_frames(tri)[:, faces])
            corners = tri[faces].reshape(n, -1, 3) - self.origin
            self.obb32 = oriented_boxes(corners).astype(np.float32)
            box_lo[n:], box_hi[n:] = corners.min(axis=1), corners.max(axis=1)
        for level in range(self.depth - 1, -1, -1):
            a, b = 1 << level, 2 << level
            box_lo[a:b] = np.minimum(box_lo[2 * a : 2 * b : 2], box_lo[2 * a + 1 : 2 * b : 2])
            box_hi[a:b] = np.maximum(box_hi[2 * a : 2 * b : 2], box_hi[2 * a + 1 : 2 * b : 2])
        aabb = np.hstack([0.5 * (box_lo + box_hi), 0.5 * (box_hi - box_lo)])
        self.aabb32 = aabb.astype(np.float32)
        margin = 1e-9 * self.size
        self.aabb_lo = box_lo + (self.origin - margin)  # float64, for ray casting
        self.aabb_hi = box_hi + (self.origin + margin)
        self.triangles = tri
        self.centre_leaf = np.flatnonzero(real[:, 0])
        centres = 0.5 * (box_lo[n:] + box_hi[n:])[self.centre_leaf] + self.origin
        self.centre_tree = cKDTree(centres)

    def descend(self, points: np.ndarray, bound2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """All (query, leaf) pairs whose boxes lie within ``sqrt(bound2)`` of the query.

        Breadth-first branch and bound from the root, one tree level per
        pass.  The box tests run in single precision on coordinates relative
        to the mesh centre; every rounding error (of the boxes and of the
        tests) is below ``1e-6`` of the magnitudes involved, so the bound is
        widened by ``4e-6 x (mesh size + distance from the centre)``: no box
        within the true bound is ever dropped.
        """
        rel = points - self.origin
        widen = 4e-6 * (self.size + np.sqrt(np.einsum("ij,ij->i", rel, rel)))
        limit = ((np.sqrt(bound2) + widen) ** 2).astype(np.float32)
        p32 = rel.astype(np.float32)
        # (query, node) pairs packed as query << 32 | node
        pairs = (np.arange(len(points), dtype=np.int64) << 32) | 1
        mask = np.int64(0xFFFFFFFF)
        for level in range(self.depth + 1):
            q, node = pairs >> 32, pairs & mask
            lb = aabb_bound(np.take(p32, q, axis=0), np.take(self.aabb32, node, axis=0))
            keep = lb <= np.take(limit, q)
            pairs = np.compress(keep, pairs)
            if level < self.depth:
                pairs = np.repeat(pairs + np.compress(keep, node), 2)  # children 2n, 2n + 1
                pairs[1::2] += 1
        # leaves: the oriented box as well
        q, leaf = pairs >> 32, (pairs & mask) - self.n_leaves
        lb = box_bound(np.take(p32, q, axis=0), np.take(self.obb32, leaf, axis=0))
        keep = lb <= np.take(limit, q)
        return np.compress(keep, q), np.compress(keep, leaf)

    # ------------------------------------------------------------ exact
    def leaf_distances(self, points: np.ndarray, leaf: np.ndarray) -> np.ndarray:
        """``(k, leaf_size)`` squared distances from ``points[i]`` to the faces of ``leaf[i]``."""
        if len(leaf) <= _CHUNK_LEAVES:
            return self._leaf_distances(points, leaf)
        return np.concatenate(
            [
                self._leaf_distances(points[s : s + _CHUNK_LEAVES], leaf[s : s + _CHUNK_LEAVES])
                for s in range(0, len(leaf), _CHUNK_LEAVES)
            ]
        )

    def _leaf_distances(self, points: np.ndarray, leaf: np.ndarray) -> np.ndarray:
        t = np.take(self.table, leaf, axis=1)
        px, py, pz = (points[:, i : i + 1] for i in range(3))
        wx, wy, wz = px - t[0], py - t[1], pz - t[2]
        x = wx * t[3]
        x += wy * t[4]
        x += wz * t[5]
        y = wx * t[6]
        y += wy * t[7]
        y += wz * t[8]
        wx *= t[9]
        wy *= t[10]
        wz *= t[11]
        z = wx
        z += wy
        z += wz
        bx, cx, cy, ex, iac, ibc, ylo = t[12:]
        # edge ab along the x axis
        s = np.maximum(x, 0.0)
        np.minimum(s, bx, out=s)
        np.subtract(x, s, out=s)
        d = s * s
        d += y * y
        np.minimum(d, _segment_dist2(x, y, cx, cy, iac), out=d)  # edge ac
        inside = cy * x >= cx * y
        xb = x - bx  # edge bc, with x measured from corner b
        np.minimum(d, _segment_dist2(xb, y, ex, cy, ibc), out=d)
        inside &= ex * y >= cy * xb
        inside &= y >= ylo
        np.copyto(d, 0.0, where=inside)
        z *= z
        d += z
        return d
