"""A detail layer over a fitted skin: displaced subdivision surface (mm, any frame).

The reference skin has ~4 mm edges (4 890 vertices), enough to animate and to
carry the head's shape, not to hold a scan's eyelid creases, lip borders,
nostril rims or a bust's carved curls.  The detail is kept the way displaced
subdivision surfaces keep it (Lee, Moreton & Hoppe 2000): the fitted skin is
the *control mesh*; ``levels`` Loop steps (:mod:`workbench.core.headgen.
subdivision`, a fixed sparse matrix ``S``) give a smooth fine surface, and
one scalar per fine vertex moves it along its unit normal onto the scan::

    fine = S @ coarse;  detailed = fine + d * normals(fine)

Because ``S`` is fixed and ``d`` rides on the normals, the same layer
re-details the skin after the coarse mesh has been animated, aged or warped
(:meth:`DetailLayer.apply`), and every fitted head of one reference shares
the fine topology.

How ``d`` is found (:func:`build_detail`): rays from each fine vertex along
``+n`` and ``-n`` (at most :data:`REACH_MM`) meet the scan; a hit counts when
the scan there faces the same side and is believed (the caller's per scan
vertex weights, 0 over hole rims, cavity walls and parts that are not the
head).  ``d`` then minimises a weighted least-squares fit to the hits plus a
membrane term over the fine edges and a weak pull to zero, so where the scan
has no data (a hole, the back of the head) the layer fades to the fitted
skin itself, smoothly, never a step.

Four safeguards keep the detailed skin a clean surface.  Each displacement
stays below a share of (a) the distance to the nearest part of the fine skin
that faces it (the other lip, an ear's other side), so two sheets moving
toward each other cannot meet, and (b) the focal distance of its sharpest
bend that way, so an offset never passes a centre of curvature.  Then any
fine triangle the displacement still turned over has its corners' values
halved, round after round, and around any pair of triangles the displacement
made cross (checked only among the triangles it moved, and only pairs that
did not cross before) the displacement fades to zero over a few edges.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import cg
from scipy.spatial import cKDTree

from workbench.core.headgen.subdivision import loop_subdivide
from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.core.raycast import RayCaster
from workbench.core.self_intersection import pairs_cross, self_intersections
from workbench.core.threads import worker_count

#: Loop steps of the detail layer over the reference skin (4 890 → 77 358 vertices,
#: ~1 mm edges)
DETAIL_LEVELS = 2
#: farthest a fine vertex looks for the scan along its normal, either way (mm); the
#: coarse fit leaves a few points of the face 4-6 mm off (nostril rims, lid creases, a
#: bust's carved curls); tuned 4 → 6 on headsq, Demosthenes and the VHP female skin
REACH_MM = 6.0
#: a hit counts when the scan's face normal and the fine normal agree this much (cos)
FACING_COS = 0.3
#: membrane weight over the fine edges, relative to a fully believed hit (tuned 0.2 →
#: 0.05 on the same three cases: the stiffer layer rounded off lid creases)
MEMBRANE = 0.05
#: pull of every displacement toward zero (the fitted skin), relative to a hit; with
#: MEMBRANE it sets how far the layer reaches into a hole (~ edge x sqrt(M / Z) ≈ 4 mm)
TO_ZERO = 0.01
#: a displacement stays below this share of the distance to the nearest part of the
#: fine surface that faces it (an ear's other side, the other lip), so two sheets moving
#: toward each other cannot meet
CLEARANCE_SHARE = 0.45
#: ... and below this share of the focal distance of the surface's sharpest bend that
#: way (an offset surface folds where it passes the centres of curvature: a helix rim
#: moved inward by more than its radius, a crease moved outward by more than its own)
FOCAL_SHARE = 0.5
#: weight (mm) of the normal in the search for the nearest opposite-facing surface, its
#: candidates per vertex, and how opposite counts (cos of the normals)
OPPOSITE_WEIGHT_MM = 3.0
OPPOSITE_K = 8
OPPOSITE_COS = -0.2
#: rounds of halving the displacement at turned-over fine triangles
RELAX_ROUNDS = 12
#: rounds of fading the displacement out around triangles it made cross, over this many
#: edges (times the round) from them
UNCROSS_ROUNDS = 3
FADE_HOPS = 3


@dataclass(frozen=True)
class DetailLayer:
    """Scalar displacements over the Loop-subdivided fitted skin.

    Attributes
    ----------
    levels : int
        Loop steps from the control mesh (the fitted skin) to the fine mesh.
    matrix : scipy.sparse.csr_matrix, shape (n_fine, n_coarse)
        Fine positions = ``matrix @ coarse positions`` (control vertex ``i`` is
        fine vertex ``i``).
    faces : (m_fine, 3) int64
        Fine triangles (children of coarse face ``f`` are rows ``4**levels * f`` ...;
        :attr:`parent_faces`).
    displacement : (n_fine,) float64
        mm along each fine vertex's unit normal (outward positive).
    observed : (n_fine,) bool
        The fine vertex found the scan along its normal (a believed hit).
    new_crossings : int
        Face pairs of the detailed skin that cross and did not in the undisplaced
        subdivided skin (0 unless the repair rounds did not suffice).
    """

    levels: int
    matrix: sparse.csr_matrix
    faces: np.ndarray
    displacement: np.ndarray
    observed: np.ndarray
    new_crossings: int = 0

    def apply(self, coarse_vertices: np.ndarray) -> Mesh:
        """The detailed skin over a coarse skin of the control topology (same frame, mm)."""
        fine = self.smooth_surface(coarse_vertices)
        return fine.with_vertices(fine.vertices + self.displacement[:, None] * vertex_normals(fine))

    def smooth_surface(self, coarse_vertices: np.ndarray) -> Mesh:
        """The subdivided coarse skin without the displacement."""
        v = np.asarray(self.matrix @ np.asarray(coarse_vertices, float))
        return self._fine_topology.with_vertices(v)

    @cached_property
    def _fine_topology(self) -> Mesh:
        """A fine mesh whose cached connectivity (edges, boundary) every surface of this layer
        takes over (:meth:`Mesh.with_vertices`): one edge search per layer, not per call."""
        return Mesh(np.zeros((self.matrix.shape[0], 3)), self.faces)

    @property
    def parent_faces(self) -> np.ndarray:
        """``(m_fine,)`` the coarse triangle each fine triangle descends from."""
        return np.arange(len(self.faces)) // 4**self.levels


def subdivision_of(
    coarse: Mesh, levels: int = DETAIL_LEVELS
) -> tuple[sparse.csr_matrix, np.ndarray]:
    """``(matrix, faces)`` of ``levels`` Loop steps over ``coarse``'s topology (boundaries
    refine as curves; the topology alone decides, so every fit of one reference agrees)."""
    sub = loop_subdivide(coarse.faces, coarse.n_vertices, levels)
    return sub.matrix.tocsr(), sub.faces


def _adjacency(edges: np.ndarray, n: int) -> sparse.csr_matrix:
    """``(n, n)`` symmetric 0/1 vertex adjacency of ``edges``."""
    adj = sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    return (adj + adj.T).tocsr()


def _hits(
    fine: Mesh,
    normals: np.ndarray,
    caster: RayCaster,
    weights: np.ndarray,
    reach: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance along the normal to the nearer believed, same-facing scan hit, and
    its belief (0 where none)."""
    scan = caster.mesh
    best = np.zeros(fine.n_vertices)
    belief = np.zeros(fine.n_vertices)
    nearest = np.full(fine.n_vertices, np.inf)
    for sign in (1.0, -1.0):
        rays = caster.first_hits(fine.vertices, sign * normals, max_distance=reach)
        ok = rays.hit.copy()
        f = np.maximum(rays.face_ids, 0)
        facing = np.einsum("ij,ij->i", scan.face_normals[f], normals)
        ok &= facing > FACING_COS
        w = np.einsum("ij,ij->i", rays.barycentric, weights[scan.faces[f]])
        ok &= w > 0.0
        closer = ok & (rays.distance < nearest)
        nearest[closer] = rays.distance[closer]
        best[closer] = sign * rays.distance[closer]
        belief[closer] = w[closer]
    return best, np.clip(belief, 0.0, 1.0)


def _clearance(fine: Mesh, normals: np.ndarray, reach: float) -> np.ndarray:
    """Per fine vertex, :data:`CLEARANCE_SHARE` of the distance to the nearest part of the
    fine surface facing it (an ear's other side, the other lip, a nostril's wall).

    Found with one nearest-neighbour query in (position, normal) space: a vertex
    ``p_j`` facing ``p_i`` has ``n_j ≈ -n_i``, so it is near ``(p_i, -a n_i)``
    among the points ``(p_j, a n_j)``.
    """
    a = OPPOSITE_WEIGHT_MM
    tree = cKDTree(np.hstack([fine.vertices, a * normals]))
    _, idx = tree.query(
        np.hstack([fine.vertices, -a * normals]), k=OPPOSITE_K, workers=worker_count()
    )
    # distance to the facing vertex's tangent plane: the facing sheet's triangles can pass
    # closer than its vertices (lips in contact are offset by up to an edge)
    gap = np.abs(
        np.einsum("ikj,ikj->ik", fine.vertices[:, None, :] - fine.vertices[idx], normals[idx])
    )
    facing = np.einsum("ij,ikj->ik", normals, normals[idx]) < OPPOSITE_COS
    gap = np.where(facing, gap, np.inf).min(axis=1)
    return np.minimum(CLEARANCE_SHARE * gap, reach)


def _focal_bounds(fine: Mesh, normals: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per fine vertex, the displacement range that keeps it short of the centres of
    curvature of its edges (normal curvature of edge i→j: 2 n_i·(p_i − p_j) / |p_i − p_j|²,
    positive where the surface bends away from the normal); ``e`` its edges."""
    i, j = np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]])
    v = fine.vertices[i] - fine.vertices[j]
    k = 2.0 * np.einsum("ij,ij->i", normals[i], v) / np.maximum(np.einsum("ij,ij->i", v, v), 1e-12)
    order = np.argsort(i, kind="stable")
    i, k = i[order], k[order]
    starts = np.flatnonzero(np.r_[True, i[1:] != i[:-1]])
    convex = np.zeros(fine.n_vertices)
    concave = np.zeros(fine.n_vertices)
    convex[i[starts]] = np.maximum.reduceat(k, starts)
    concave[i[starts]] = np.maximum.reduceat(-k, starts)
    low = -FOCAL_SHARE / np.maximum(convex, 1e-6)
    high = FOCAL_SHARE / np.maximum(concave, 1e-6)
    return low, high


def _solve(target: np.ndarray, weight: np.ndarray, adj: sparse.csr_matrix) -> np.ndarray:
    """argmin_d  Σ w (d - t)² + MEMBRANE Σ_edges (d_i - d_j)² + TO_ZERO Σ d² (``adj``: the
    fine vertices' adjacency, one entry per edge each way)."""
    lap = sparse.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    a = (sparse.diags(weight + TO_ZERO) + MEMBRANE * lap).tocsr()
    b = weight * target
    pre = sparse.diags(1.0 / a.diagonal())
    d, _info = cg(a, b, x0=np.where(weight > 0, target, 0.0), rtol=1e-8, maxiter=500, M=pre)
    return np.asarray(d)


def _unturn(fine: Mesh, normals: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Halve the displacement at the corners of turned-over fine triangles until none is."""
    before = fine.face_normals
    d = d.copy()
    for _ in range(RELAX_ROUNDS):
        moved = fine.with_vertices(fine.vertices + d[:, None] * normals)
        turned = (moved.face_normals * before).sum(axis=1) <= 0.0
        if not turned.any():
            return d
        d[np.unique(fine.faces[turned])] *= 0.5
    moved = fine.with_vertices(fine.vertices + d[:, None] * normals)
    d[np.unique(fine.faces[(moved.face_normals * before).sum(axis=1) <= 0.0])] = 0.0
    return d


def _uncross(
    fine: Mesh, normals: np.ndarray, d: np.ndarray, adj: sparse.csr_matrix
) -> tuple[np.ndarray, int]:
    """Fade the displacement out around fine triangles it made cross others.

    Returns the displacement and how many crossing pairs it still adds (0 unless
    :data:`UNCROSS_ROUNDS` did not suffice); the returned field is always the one
    checked.  A crossing is *added* when the pair does not cross in the undisplaced
    surface.
    """
    d = d.copy()
    n = fine.n_vertices
    # pairs of triangles the displacement leaves where they were cross as they did; after a
    # round, only pairs with a triangle that round changed can have changed
    changed = np.abs(d[fine.faces]).max(axis=1) > 0.0
    for round_ in range(UNCROSS_ROUNDS + 1):
        moved = fine.with_vertices(fine.vertices + d[:, None] * normals)
        pairs = self_intersections(moved, among=changed).pairs
        if len(pairs):
            pairs = pairs[~pairs_cross(fine, pairs)]
        if not len(pairs) or round_ == UNCROSS_ROUNDS:
            return d, int(len(pairs))
        # hops along the surface from the crossing triangles' corners; the displacement
        # rises back over FADE_HOPS edges (the last round clears a wider patch)
        hops_out = FADE_HOPS * (round_ + 1)
        hops = np.full(n, np.inf)
        reached = np.zeros(n, bool)
        reached[np.unique(fine.faces[pairs])] = True
        hops[reached] = 0.0
        for k in range(1, hops_out + 1):
            reached = reached | (np.asarray(adj @ reached.astype(float)).ravel() > 0)
            hops[reached & np.isinf(hops)] = k
        factor = np.clip(hops / hops_out, 0.0, 1.0)
        changed = ((factor < 1.0) & (d != 0.0))[fine.faces].any(axis=1)
        d *= factor
    return d, 0  # not reached: the loop returns at its last round


def build_detail(
    coarse: Mesh,
    scan: Mesh,
    weights: np.ndarray,
    *,
    levels: int = DETAIL_LEVELS,
    reach: float = REACH_MM,
    fixed: np.ndarray | None = None,
) -> DetailLayer:
    """The detail layer that carries ``scan``'s surface onto the subdivided ``coarse`` skin.

    ``coarse`` (the fitted skin) and ``scan`` (wound outward) in one frame, mm;
    ``weights`` per scan vertex, 0..1 (how much that part of the scan is
    believed to be the head's skin).  ``fixed`` (per coarse vertex, bool)
    marks skin that keeps no detail (the layer fades to zero over it).  Rays
    use the scan's shared caster (:meth:`RayCaster.shared`).
    """
    matrix, faces = subdivision_of(coarse, levels)
    fine = Mesh(np.asarray(matrix @ coarse.vertices), faces)
    normals = vertex_normals(fine)
    caster = RayCaster.shared(scan)
    w_scan = np.clip(np.asarray(weights, float), 0.0, 1.0)
    target, belief = _hits(fine, normals, caster, w_scan, reach)
    room = _clearance(fine, normals, reach)
    edges = fine.edges_unique
    adj = _adjacency(edges, fine.n_vertices)
    low, high = _focal_bounds(fine, normals, edges)
    low, high = np.maximum(low, -room), np.minimum(high, room)
    if fixed is not None:
        keep = np.asarray(matrix @ np.asarray(fixed, float)).ravel() < 0.5
        low, high = np.where(keep, low, 0.0), np.where(keep, high, 0.0)
        belief = np.where(keep, belief, 0.0)
    target = np.clip(target, low, high)
    d = _solve(target, belief, adj)
    d = np.clip(d, low, high)
    d = _unturn(fine, normals, d)
    d, crossings = _uncross(fine, normals, d, adj)
    layer = DetailLayer(levels, matrix, faces, d, belief > 0.0, crossings)
    layer.__dict__["_fine_topology"] = fine  # its edges are found already
    return layer
