"""Last step of the reference head: lift skin that lies closer to the bone than a minimum tissue.

The skull is fitted under the authored skin by a landmark warp
(:func:`workbench.services.templates.template.fit_skull_to_skin`) whose
clearance constraints lie about 10 mm apart.  Between two of them a ridge
of bone can still come closer to the skin than the minimum soft tissue: the
lateral orbital rims beside the outer eye corners were left 1.2-1.5 mm under
the skin (published depths there are several mm), the medial orbital rims
1.4 mm.  The tools that use the head take its skin-to-bone distances as
tissue (the age tool restores them, a reconstruction starts from them), so
thin spots there would be copied into every result.  Aiming the fit's constraints
deeper bent the thin orbital rim further into the orbit and unsettled the
heads adapted from this one to CT scans, so the skin is lifted instead,
locally and by up to about a millimetre: :func:`lift_skin_off_bone`.

The skin landmarks do not move (the facial measurements the skin was
fitted to, the Frankfort plane through po and or, and the tissue depths of
the skull fit are all taken at them): no lift starts within
:data:`FALLOFF_MM` of one, so none reaches it, and the skin within a few mm
of a landmark can stay thinner (the infraorbital margin, around or and mio).

Units and frame: mm, head frame (x to the subject's left, x = 0 the
midsagittal plane, y up, z forward, Frankfort Horizontal y = 0).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex

#: Skin closer to the bone than this (mm) is lifted.
MIN_TISSUE_MM = 2.0
#: Surface distance (mm) over which a lift fades out around a thin vertex.
FALLOFF_MM = 5.0
#: Lifts aim this far (mm) beyond the minimum, so that one or two rounds settle.
LIFT_MARGIN_MM = 0.05
_MIRROR = np.array([-1.0, 1.0, 1.0])


def lift_skin_off_bone(
    skin: Mesh,
    bones: Sequence[Mesh],
    min_tissue_mm: float = MIN_TISSUE_MM,
    *,
    held: Sequence[int] = (),
    falloff_mm: float = FALLOFF_MM,
    rounds: int = 6,
) -> np.ndarray:
    """Skin vertex positions ``(n, 3)`` (mm) lifted to ``min_tissue_mm`` over the ``bones``.

    Each round measures every skin vertex against the closed ``bones``
    (signed, so a vertex inside bone counts as thinner than zero).  A thin
    vertex *i* (distance ``d_i < min_tissue_mm``) needs
    ``need_i = min_tissue_mm + LIFT_MARGIN_MM - d_i`` along ``a_i``, the unit
    vector from its closest bone point to it (out of the bone for a vertex
    inside).  Every vertex *j* moves by ``max_i need_i w_ij`` along the
    ``need_i w_ij``-weighted mean of the ``a_i``, with
    ``w_ij = (1 - (g_ij / falloff_mm)^2)^2`` for the distance ``g_ij`` along
    the skin's edges (so nothing moves across the eye or mouth openings) up
    to ``falloff_mm`` and 0 beyond: 1 at the thin vertex, falling to 0 with
    zero slope.  Thin vertices closer than ``falloff_mm`` to a ``held`` vertex
    are not lifted, so the held vertices never move (and a lift never pins
    a dimple around one); they can stay thin.  A mirror-symmetric skin
    (x = 0 the midline) stays symmetric: of two mirror vertices both take the
    larger move, mirrored, and midline vertices stay on x = 0.  Rounds repeat
    until no vertex that may be lifted is thin, or ``rounds`` are done.  A
    skin that has the minimum everywhere comes back unchanged, bit for bit.
    """
    v = np.array(skin.vertices, dtype=float)
    indices = [MeshIndex(b) for b in bones]
    graph = _edge_graph(skin)
    partner = _mirror_partner(v)
    pinned = np.unique(np.asarray(held, dtype=np.int64))
    free = np.ones(len(v), bool)  # may be lifted: falloff_mm or more from every held vertex
    if len(pinned):
        near = dijkstra(graph, directed=False, indices=pinned, limit=falloff_mm)
        free = ~np.isfinite(near).any(axis=0)
    for _ in range(rounds):
        depth, away = _clearance(v, indices)
        thin = np.flatnonzero((depth < min_tissue_mm) & free)
        if not len(thin):
            break
        need = min_tissue_mm + LIFT_MARGIN_MM - depth[thin]
        g = dijkstra(graph, directed=False, indices=thin, limit=falloff_mm)
        w = _bump(g, falloff_mm) * need[:, None]  # (k, n)
        direction = np.einsum("kn,kc->nc", w, away[thin])
        length = np.linalg.norm(direction, axis=1)
        moving = length > 0.0
        move = np.zeros_like(v)
        move[moving] = w.max(axis=0)[moving, None] * direction[moving] / length[moving, None]
        move = _symmetric(move, partner)
        move[pinned] = 0.0  # (zero already, unless held is not mirror-symmetric)
        v = v + move
    return v


def _bump(g: np.ndarray, radius: float) -> np.ndarray:
    """``(1 - (g / radius)^2)^2`` up to ``radius``, 0 beyond (``g`` may be inf)."""
    t = np.minimum(g / radius, 1.0)
    return (1.0 - t * t) ** 2


def _clearance(v: np.ndarray, indices: Sequence[MeshIndex]) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance of ``v`` to the nearest bone (mm, + outside) and the unit way out."""
    depth = np.full(len(v), np.inf)
    away = np.zeros_like(v)
    for index in indices:
        cp, signed = index.signed_closest_points(v)
        off = v - cp.points
        length = np.linalg.norm(off, axis=1)
        # on the surface the offset has no direction: take the bone's outward normal there
        out = index.pseudo_normals(cp.face_ids, cp.barycentric)
        far = length > 1e-9
        out[far] = np.sign(signed[far])[:, None] * off[far] / length[far, None]
        closer = signed < depth
        depth[closer] = signed[closer]
        away[closer] = out[closer]
    return depth, away


def _edge_graph(mesh: Mesh) -> csr_matrix:
    """Sparse ``(n, n)`` matrix of the edge lengths of ``mesh`` (mm), each edge once."""
    f = np.asarray(mesh.faces)
    pairs = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    a, b = np.unique(pairs, axis=0).T  # (a sparse matrix would add up duplicates)
    length = np.linalg.norm(mesh.vertices[a] - mesh.vertices[b], axis=1)
    n = mesh.n_vertices
    return coo_matrix((length, (a, b)), shape=(n, n)).tocsr()


def _mirror_partner(v: np.ndarray) -> np.ndarray | None:
    """Index of each vertex's mirror image across x = 0; None if the skin is not symmetric."""
    dist, partner = cKDTree(v).query(v * _MIRROR)
    return partner if dist.max() < 1e-6 else None


def _symmetric(move: np.ndarray, partner: np.ndarray | None) -> np.ndarray:
    """``move`` (n, 3) with each mirror pair given the larger of the two moves, mirrored."""
    if partner is None:
        return move
    mirrored = move[partner] * _MIRROR
    take = np.linalg.norm(mirrored, axis=1) > np.linalg.norm(move, axis=1)
    out = np.where(take[:, None], mirrored, move)
    out[partner == np.arange(len(move)), 0] = 0.0  # the midline stays on x = 0
    return out
