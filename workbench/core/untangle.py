"""Undo small crossings and fold-overs a registration left in a fitted surface.

Units mm.  A non-rigid fit can pull a few tiny triangles through their
neighbours where the template is finely meshed and the target coarse (the
lid corners and mouth corners of a head skin on a 3 mm CT): their faces
cross (:func:`~workbench.core.self_intersection.self_intersections`) or
turn over against the template.  :func:`untangle` smooths only those
places: the vertices of the offending faces and a ring of neighbours move
toward the mean of their neighbours plus the template's own offset from its
neighbours' mean there (its Laplacian coordinates; without a template, the
plain mean), the rest stays.
If a round leaves crossings the ring widens.  Crossings the template itself
has (``allowed``) are not touched.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from workbench.core.mesh import Mesh
from workbench.core.self_intersection import self_intersections

#: smoothing steps per round, and the step's weight toward the neighbours' mean
STEPS, WEIGHT = 4, 0.5


@dataclass(frozen=True)
class Untangled:
    """Result of :func:`untangle`.

    Attributes
    ----------
    mesh : Mesh
        Same topology, vertices moved where needed (mm).
    moved : (n,) bool
        Vertices that moved.
    rounds : int
        Rounds that smoothed something.
    crossings_before, crossings_after, folds_before, folds_after : int
        Crossing face pairs (beyond ``allowed``) and turned-over faces.
    """

    mesh: Mesh
    moved: np.ndarray
    rounds: int
    crossings_before: int
    crossings_after: int
    folds_before: int
    folds_after: int


def _offending(
    mesh: Mesh, reference_normals: np.ndarray | None, allowed: set[tuple[int, int]]
) -> tuple[np.ndarray, int, int]:
    pairs = [p for p in self_intersections(mesh).pairs.tolist() if tuple(p) not in allowed]
    faces = np.array(sorted({f for p in pairs for f in p}), dtype=np.int64)
    folds = 0
    if reference_normals is not None:
        turned = np.flatnonzero((mesh.face_normals * reference_normals).sum(axis=1) < 0.0)
        allowed_faces = {f for p in allowed for f in p}
        turned = np.array([f for f in turned if f not in allowed_faces], dtype=np.int64)
        folds = len(turned)
        faces = np.union1d(faces, turned)
    return faces, len(pairs), folds


def untangle(
    mesh: Mesh,
    *,
    reference: Mesh | None = None,
    allowed: Iterable[tuple[int, int]] = (),
    rounds: int = 8,
    fixed: np.ndarray | None = None,
) -> Untangled:
    """Smooth away the crossings (and, given ``reference``, the fold-overs) of ``mesh``.

    Parameters
    ----------
    reference : Mesh, optional
        The template with the same faces: a face whose normal turned against
        its normal there is a fold-over.
    allowed : face pairs (i < j) the template itself has crossing; left alone.
    rounds : int
        At most this many rounds; round ``r`` smooths the offending faces'
        vertices and ``r`` rings of neighbours.
    fixed : (n,) bool, optional
        Vertices that must not move (user-placed landmarks' triangles).
    """
    allowed_set = {(min(int(a), int(b)), max(int(a), int(b))) for a, b in allowed}
    ref_n = None if reference is None else reference.face_normals
    n = mesh.n_vertices
    e = mesh.edges_unique
    adj = sparse.coo_matrix((np.ones(2 * len(e)), (e.ravel(), e[:, ::-1].ravel())), shape=(n, n))
    adj = adj.tocsr()
    degree = np.maximum(np.asarray(adj.sum(axis=1)).ravel(), 1.0)
    v = mesh.vertices.copy()
    moved = np.zeros(n, bool)
    faces, crossings0, folds0 = _offending(mesh, ref_n, allowed_set)
    crossings, folds = crossings0, folds0
    done = 0
    # with a template, smooth toward its local shape (its Laplacian coordinates): the
    # fine seams of lids and lips keep their form instead of being flattened and flipped
    delta = np.zeros_like(v)
    if reference is not None:
        delta = reference.vertices - (adj @ reference.vertices) / degree[:, None]
    for r in range(1, rounds + 1):
        if len(faces) == 0:
            break
        sel = np.zeros(n, bool)
        sel[mesh.faces[faces].ravel()] = True
        for _ in range(r):
            sel |= (adj @ sel.astype(float)) > 0
        if fixed is not None:
            sel &= ~fixed
        if not sel.any():
            break
        for _ in range(STEPS):
            goal = (adj @ v) / degree[:, None] + delta
            v[sel] += WEIGHT * (goal[sel] - v[sel])
        moved |= sel
        done = r
        faces, crossings, folds = _offending(mesh.with_vertices(v), ref_n, allowed_set)
    return Untangled(mesh.with_vertices(v), moved, done, crossings0, crossings, folds0, folds)
