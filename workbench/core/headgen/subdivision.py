"""Loop subdivision of triangle meshes with boundaries, creases and corners (numpy/scipy).

One step of Loop's scheme (Loop 1987) splits every triangle into four and
computes every new position as a fixed linear combination of the old ones,
so a step is returned as a sparse *subdivision matrix* ``S`` with
``new_vertices = S @ old_vertices``.  Because the map is linear, callers can
fit control positions to wanted fine positions by least squares (the
authoring of the reference head does) and can carry any per-vertex quantity
(positions in mm, texture coordinates, displacement fields) through the same
matrix.

Rules
-----
* Old ("even") vertices keep their index; new ("odd") edge vertices are
  appended after them, one per unique edge, in the order of
  :attr:`LoopStep.edges`.
* Interior even vertex of valence ``n``: ``(1 - n b) v + b sum(neighbours)``
  with Loop's ``b = (5/8 - (3/8 + cos(2 pi / n) / 4)^2) / n``.
* Interior odd vertex on edge ``(a, b)`` with opposite corners ``c, d``:
  ``3/8 (a + b) + 1/8 (c + d)``.
* Boundary and crease edges follow the cubic B-spline curve rules
  (Hoppe et al. 1994): odd ``(a + b) / 2``; an even vertex on exactly two
  sharp edges ``3/4 v + 1/8 (a + b)`` (its sharp neighbours only), so a
  boundary loop (an eye opening, the mouth slit) refines as a curve of its
  own and the surface never pulls away from it.
* Corner vertices (given explicitly, or on more than two sharp edges, or on
  exactly one) stay where they are.

Units: whatever the input positions are in (mm for the head); the scheme is
affine-invariant, so frames do not matter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse


@dataclass(frozen=True)
class LoopStep:
    """One subdivision step.

    Attributes
    ----------
    matrix : scipy.sparse.csr_matrix, shape (n_old + n_edges, n_old)
        New positions = ``matrix @ old positions``.
    faces : (4 m, 3) int64
        New triangles; children of old face ``f`` are rows ``4 f .. 4 f + 3``
        (corner children at ``a``, ``b``, ``c``, then the middle one).
    edges : (n_edges, 2) int64
        Sorted old vertex pairs; edge ``e`` became new vertex ``n_old + e``.
    creases : (k, 2) int64
        Sharp (crease) edges of the new mesh, sorted pairs, excluding the
        boundary (which is implied by the faces).
    """

    matrix: sparse.csr_matrix
    faces: np.ndarray
    edges: np.ndarray
    creases: np.ndarray

    @property
    def n_old(self) -> int:
        return int(self.matrix.shape[1])

    @property
    def parent_face(self) -> np.ndarray:
        """``(4 m,)`` index of the old face each new face came from."""
        return np.repeat(np.arange(len(self.faces) // 4), 4)


def _edge_table(faces: np.ndarray, n: int):
    f = np.asarray(faces, np.int64)
    m = len(f)
    half = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])  # row h*m+i
    opp = np.concatenate([f[:, 2], f[:, 0], f[:, 1]])
    key = np.sort(half, axis=1)
    code = key[:, 0] * n + key[:, 1]
    uniq, inv, counts = np.unique(code, return_inverse=True, return_counts=True)
    edges = np.stack([uniq // n, uniq % n], axis=1)
    return edges, inv.reshape(3, m).T, counts, opp, inv


def loop_step(
    faces: np.ndarray,
    n_vertices: int,
    creases: np.ndarray | None = None,
    corners: np.ndarray | None = None,
) -> LoopStep:
    """Build one Loop subdivision step for a manifold triangle mesh.

    Parameters
    ----------
    faces : (m, 3) int
        Triangles (counter-clockwise seen from outside).
    n_vertices : int
        Number of vertices of the input mesh.
    creases : (k, 2) int, optional
        Edges to keep sharp (each must be an edge of the mesh).
    corners : (c,) int, optional
        Vertices that must not move (e.g. eye and mouth corners).
    """
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    n = int(n_vertices)
    edges, face_edges, counts, opp, inv = _edge_table(faces, n)
    ne = len(edges)
    if (counts > 2).any():
        raise ValueError(
            f"{int((counts > 2).sum())} non-manifold edges: Loop subdivision needs a manifold mesh"
        )
    sharp = counts == 1
    crease_in = (
        np.zeros((0, 2), np.int64)
        if creases is None
        else np.sort(np.asarray(creases, np.int64).reshape(-1, 2), axis=1)
    )
    if len(crease_in):
        code = edges[:, 0] * n + edges[:, 1]
        ccode = crease_in[:, 0] * n + crease_in[:, 1]
        pos = np.searchsorted(code, ccode)
        ok = (pos < ne) & (code[np.minimum(pos, ne - 1)] == ccode)
        if not ok.all():
            raise ValueError(f"{int((~ok).sum())} crease edges are not edges of the mesh")
        is_crease = np.zeros(ne, bool)
        is_crease[pos] = True
        sharp = sharp | is_crease
    else:
        is_crease = np.zeros(ne, bool)

    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []

    # ---------------------------------------------------------------- odd vertices
    # opposite corners of every edge: gather from the half-edge table
    opp_sum_rows = np.concatenate([inv, inv])
    a, b = edges[:, 0], edges[:, 1]
    e_ids = np.arange(ne)
    smooth = ~sharp
    # endpoints
    w_end = np.where(smooth, 3.0 / 8.0, 0.5)
    rows += [n + e_ids, n + e_ids]
    cols += [a, b]
    vals += [w_end, w_end]
    # opposite corners (only for smooth edges, which have exactly two)
    smooth_half = smooth[inv]
    rows.append(n + inv[smooth_half])
    cols.append(opp[smooth_half])
    vals.append(np.full(int(smooth_half.sum()), 1.0 / 8.0))
    del opp_sum_rows

    # ---------------------------------------------------------------- even vertices
    valence = np.bincount(edges.ravel(), minlength=n)
    sharp_count = np.bincount(edges[sharp].ravel(), minlength=n)
    corner = (sharp_count == 1) | (sharp_count > 2)
    if corners is not None and len(corners):
        corner[np.asarray(corners, np.int64)] = True
    is_sharp_v = (sharp_count == 2) & ~corner
    interior_v = (sharp_count == 0) & ~corner

    nv = np.maximum(valence, 1).astype(float)
    beta = (5.0 / 8.0 - (3.0 / 8.0 + 0.25 * np.cos(2.0 * np.pi / nv)) ** 2) / nv
    # neighbour contributions
    ea = np.concatenate([a, b])
    eb = np.concatenate([b, a])
    esharp = np.concatenate([sharp, sharp])
    w_nb = np.where(interior_v[ea], beta[ea], 0.0) + np.where(
        is_sharp_v[ea] & esharp, 1.0 / 8.0, 0.0
    )
    keep = w_nb != 0.0
    rows.append(ea[keep])
    cols.append(eb[keep])
    vals.append(w_nb[keep])
    self_w = np.where(interior_v, 1.0 - valence * beta, np.where(is_sharp_v, 0.75, 1.0))
    isolated = valence == 0
    self_w = np.where(isolated, 1.0, self_w)
    rows.append(np.arange(n))
    cols.append(np.arange(n))
    vals.append(self_w)

    mat = sparse.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n + ne, n)
    )
    mat.sum_duplicates()

    # ---------------------------------------------------------------- faces
    ev = n + face_edges  # (m, 3): new vertex on edge (0,1), (1,2), (2,0)
    v0, v1, v2 = faces[:, 0], faces[:, 1], faces[:, 2]
    e01, e12, e20 = ev[:, 0], ev[:, 1], ev[:, 2]
    new_faces = np.stack(
        [
            np.stack([v0, e01, e20], 1),
            np.stack([e01, v1, e12], 1),
            np.stack([e20, e12, v2], 1),
            np.stack([e01, e12, e20], 1),
        ],
        axis=1,
    ).reshape(-1, 3)

    # crease edges of the child mesh (halves of the parent crease edges)
    ce = np.nonzero(is_crease)[0]
    child = np.concatenate(
        [np.stack([edges[ce, 0], n + ce], 1), np.stack([n + ce, edges[ce, 1]], 1)]
    )
    child = np.sort(child, axis=1)
    return LoopStep(matrix=mat, faces=new_faces, edges=edges, creases=child)


@dataclass(frozen=True)
class Subdivided:
    """Result of several Loop steps applied to a control mesh.

    ``matrix`` maps control positions to fine positions (``(n_fine, n_ctrl)``);
    control vertex ``i`` is fine vertex ``i``; ``parent_face[j]`` is the
    control face fine face ``j`` descends from.
    """

    matrix: sparse.csr_matrix
    faces: np.ndarray
    parent_face: np.ndarray
    creases: np.ndarray


def loop_subdivide(
    faces: np.ndarray,
    n_vertices: int,
    levels: int = 1,
    creases: np.ndarray | None = None,
    corners: np.ndarray | None = None,
) -> Subdivided:
    """Apply ``levels`` Loop steps; returns the composed subdivision matrix.

    Corners stay corners at every level (their indices do not change).
    """
    if levels < 0:
        raise ValueError("levels must be >= 0")
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    n = int(n_vertices)
    total = sparse.identity(n, format="csr")
    parent = np.arange(len(faces))
    cr = (
        np.zeros((0, 2), np.int64)
        if creases is None
        else np.asarray(creases, np.int64).reshape(-1, 2)
    )
    for _ in range(levels):
        step = loop_step(faces, n, cr, corners)
        total = (step.matrix @ total).tocsr()
        parent = parent[step.parent_face]
        faces = step.faces
        cr = step.creases
        n = step.matrix.shape[0]
    return Subdivided(matrix=total, faces=faces, parent_face=parent, creases=cr)
