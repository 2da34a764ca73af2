"""Soft-tissue thickness of a skin surface over a bone surface, measured and set.

Units mm, one frame for skin and bone.  *Thickness* here is the distance
from a skin vertex to the nearest point of the bone surface, signed
(negative inside the bone) — the quantity a CT shows and the one the
validation metric's "within 35 mm of the bone" uses.  Depth tables measure
along a dowel from a bony landmark, which agrees with it on flat and convex
bone (forehead, zygoma, chin) and is larger over concavities; callers that
calibrate against a table do so at the table's sites (see
:mod:`workbench.services.tissue.tissue_model`).

:func:`set_thickness` moves skin vertices along their normals until their
thickness reaches a target, with the correction smoothed over the skin so
the surface keeps its own shape (a nearest-point distance jumps where the
nearest bone switches from one ridge to another; a smoothed correction does
not).  Feature vertices (nose, lips, eyelids, ears) get no correction of
their own: they take a membrane (harmonic) fill of the correction around
them, so a nose moves as a whole and keeps its shape.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.core.spatial import MeshIndex


def adjacency(mesh: Mesh) -> sparse.csr_matrix:
    """Symmetric vertex adjacency (1 per edge)."""
    e, n = mesh.edges_unique, mesh.n_vertices
    a = sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return (a + a.T).tocsr()


def smooth_field(adj: sparse.csr_matrix, values: np.ndarray, passes: int) -> np.ndarray:
    """``passes`` rounds of half-weight umbrella averaging over the mesh (any trailing shape)."""
    deg = np.maximum(np.asarray(adj.sum(axis=1)).ravel(), 1.0)
    v = np.asarray(values, float)
    for _ in range(passes):
        avg = (adj @ v) / (deg if v.ndim == 1 else deg[:, None])
        v = 0.5 * v + 0.5 * avg
    return v


def harmonic_fill(
    adj: sparse.csr_matrix, known: np.ndarray, values: np.ndarray, pull: float = 1e-6
) -> np.ndarray:
    """Values on ``known`` vertices kept, the rest a membrane (harmonic) fill of them.

    A weak ``pull`` toward zero decides vertices in pieces with no known value.
    """
    out = np.where(known, values, 0.0)
    free = np.flatnonzero(~known)
    if len(free) and known.any():
        deg = np.asarray(adj.sum(axis=1)).ravel()
        system = (sparse.diags(deg[free] + pull) - adj[free][:, free]).tocsc()
        rhs = adj[free][:, np.flatnonzero(known)] @ values[known]
        out[free] = spsolve(system, rhs)
    return out


def thickness(points: np.ndarray, bone: MeshIndex) -> np.ndarray:
    """Signed nearest distance of ``points`` to the (outward-wound) bone surface (mm)."""
    return bone.signed_distance(points)


def set_thickness(
    skin: Mesh,
    bone: MeshIndex,
    target_mm: np.ndarray,
    *,
    adjust: np.ndarray,
    features: np.ndarray | None = None,
    rounds: int = 3,
    passes: int = 6,
    max_step_mm: float = 25.0,
) -> np.ndarray:
    """Skin vertices moved along their normals toward thickness ``target_mm`` (mm).

    Parameters
    ----------
    adjust : (n,) bool
        Vertices whose thickness is set.
    features : (n,) bool, optional
        Vertices that follow the correction around them (harmonic fill)
        instead of their own.  Vertices in neither set do not move.
    rounds : int
        Measure-correct rounds (moving along a normal changes the nearest
        bone point, so the correction is re-measured).
    passes : int
        Smoothing passes over the correction each round.

    Returns the new ``(n, 3)`` vertices.
    """
    adj = adjacency(skin)
    features = np.zeros(skin.n_vertices, bool) if features is None else features & ~adjust
    v = np.array(skin.vertices, float)
    moving = adjust | features
    for _ in range(rounds):
        d = thickness(v, bone)
        corr = np.where(adjust, np.clip(target_mm - d, -max_step_mm, max_step_mm), 0.0)
        corr = smooth_field(adj, corr, passes)
        corr = np.where(adjust, corr, 0.0)
        if features.any():
            corr = harmonic_fill(adj, adjust | ~moving, corr)
        n = vertex_normals(skin.with_vertices(v))
        v = v + corr[:, None] * n * moving[:, None]
    return v
