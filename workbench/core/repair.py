"""Explicit mesh repairs.  Nothing here runs unless a caller asks for it.

Each function returns a :class:`Repaired` value: the new mesh, a map from
new vertex indices to the old ones (so landmarks and evidence references can
be followed), and one sentence saying what changed, for the audit log.

Units: mm.  Tolerances carry their unit in the argument name.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.mesh import Mesh, boundary_loops, degenerate_face_mask, duplicate_face_mask
from workbench.core.unique import unique_ints


@dataclass(frozen=True)
class Repaired:
    """Result of one repair step.

    Attributes
    ----------
    mesh : Mesh
    vertex_source : (n_new,) int64
        Old index of every new vertex.
    message : str
        What was changed (empty string when nothing was).
    """

    mesh: Mesh
    vertex_source: np.ndarray
    message: str

    @property
    def changed(self) -> bool:
        return bool(self.message)


def _unchanged(mesh: Mesh) -> Repaired:
    return Repaired(mesh, np.arange(mesh.n_vertices), "")


def _keep_faces(mesh: Mesh, keep: np.ndarray, what: str) -> Repaired:
    removed = int((~keep).sum())
    if removed == 0:
        return _unchanged(mesh)
    return Repaired(
        Mesh(mesh.vertices, mesh.faces[keep]),
        np.arange(mesh.n_vertices),
        f"removed {removed} {what}",
    )


def _drop_vertices(
    vertices: np.ndarray, faces: np.ndarray, drop: np.ndarray
) -> tuple[Mesh, np.ndarray]:
    """Remove the vertices flagged in ``drop`` (no face may use them) and renumber."""
    keep = ~drop
    new_index = np.cumsum(keep) - 1
    return Mesh(vertices[keep], new_index[faces]), np.flatnonzero(keep)


def _used(n_vertices: int, faces: np.ndarray) -> np.ndarray:
    used = np.zeros(n_vertices, bool)
    used[faces.ravel()] = True
    return used


def remove_unreferenced_vertices(mesh: Mesh) -> Repaired:
    """Drop vertices no triangle uses and renumber the faces."""
    unused = ~_used(mesh.n_vertices, mesh.faces)
    if not unused.any():
        return _unchanged(mesh)
    new_mesh, source = _drop_vertices(mesh.vertices, mesh.faces, unused)
    return Repaired(new_mesh, source, f"removed {int(unused.sum())} unreferenced vertices")


def remove_nonfinite(mesh: Mesh) -> Repaired:
    """Drop NaN/inf vertices and the triangles touching them (nothing else)."""
    bad = ~np.isfinite(mesh.vertices).all(axis=1)
    if not bad.any():
        return _unchanged(mesh)
    keep = ~bad[mesh.faces].any(axis=1)
    new_mesh, source = _drop_vertices(mesh.vertices, mesh.faces[keep], bad)
    return Repaired(
        new_mesh,
        source,
        f"removed {int(bad.sum())} non-finite vertices and {int((~keep).sum())} triangles",
    )


def remove_degenerate_faces(mesh: Mesh, area_tol_mm2: float = 1e-12) -> Repaired:
    return _keep_faces(mesh, ~degenerate_face_mask(mesh, area_tol_mm2), "degenerate triangles")


def remove_duplicate_faces(mesh: Mesh) -> Repaired:
    return _keep_faces(mesh, ~duplicate_face_mask(mesh), "duplicate triangles")


def merge_close_vertices(mesh: Mesh, tol_mm: float = 1e-6) -> Repaired:
    """Weld vertices closer than ``tol_mm`` (keeps the lowest index of each cluster)."""
    if mesh.n_vertices == 0:
        return _unchanged(mesh)
    finite = np.flatnonzero(np.isfinite(mesh.vertices).all(axis=1))
    pairs = cKDTree(mesh.vertices[finite]).query_pairs(tol_mm, output_type="ndarray")
    if len(pairs) == 0:
        return _unchanged(mesh)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = mesh.n_vertices
    pairs = finite[pairs]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    first = np.full(label.max() + 1, n)
    np.minimum.at(first, label, np.arange(n))
    remap = first[label]
    merged = remap != np.arange(n)  # welded into a lower index
    new_mesh, source = _drop_vertices(mesh.vertices, remap[mesh.faces], merged)
    return Repaired(
        new_mesh, source, f"merged {int(merged.sum())} vertices closer than {tol_mm:g} mm"
    )


def keep_largest_component(mesh: Mesh) -> Repaired:
    """Keep the edge-connected piece with the most triangles."""
    labels = mesh.face_components
    if len(labels) == 0 or labels.max() == 0:
        return _unchanged(mesh)
    sizes = np.bincount(labels)
    keep = labels == sizes.argmax()
    # drop the vertices of the removed pieces, not other unreferenced ones
    orphaned = _used(mesh.n_vertices, mesh.faces[~keep]) & ~_used(mesh.n_vertices, mesh.faces[keep])
    new_mesh, source = _drop_vertices(mesh.vertices, mesh.faces[keep], orphaned)
    return Repaired(
        new_mesh,
        source,
        f"kept the largest of {len(sizes)} pieces ({int(keep.sum())} of {mesh.n_faces} triangles)",
    )


def fill_small_holes(mesh: Mesh, max_edges: int = 30) -> Repaired:
    """Close boundary loops of at most ``max_edges`` edges with a centroid fan.

    Larger holes (e.g. a missing vault or the cut at the edge of a CT field of
    view) are left open: they are evidence, not noise.
    """
    loops = [loop for loop in boundary_loops(mesh) if 3 <= len(loop) <= max_edges]
    if not loops:
        return _unchanged(mesh)
    verts = [mesh.vertices]
    faces = [mesh.faces]
    next_index = mesh.n_vertices
    for loop in loops:
        centre = mesh.vertices[loop].mean(axis=0)
        verts.append(centre[None])
        # boundary edges run a->b along existing triangles; the cap runs b->a
        ring = np.stack([np.roll(loop, -1), loop, np.full(len(loop), next_index)], axis=1)
        faces.append(ring)
        next_index += 1
    filled = Mesh(np.concatenate(verts), np.concatenate(faces))
    source = np.concatenate([np.arange(mesh.n_vertices), np.full(len(loops), -1)])
    return Repaired(filled, source, f"filled {len(loops)} holes of up to {max_edges} edges")


def clean(mesh: Mesh) -> tuple[Mesh, list[str]]:
    """The usual sequence of safe repairs; returns the mesh and what was done."""
    messages: list[str] = []
    for step in (
        remove_nonfinite,
        remove_degenerate_faces,
        remove_duplicate_faces,
        remove_unreferenced_vertices,
    ):
        result = step(mesh)
        if result.changed:
            messages.append(result.message)
        mesh = result.mesh
    return mesh, messages


def weld_coincident_vertices(mesh: Mesh, step_mm: float) -> tuple[Repaired, np.ndarray]:
    """Weld vertices that fall in the same ``step_mm`` grid cell (a triangle soup, where
    every triangle has its own copies of its corners, or seams a scanner split).

    One pass of a 1-D ``np.unique`` on integer cell keys: no neighbour search, no
    pairwise distances, so a soup of millions of triangles welds in seconds.
    Exact copies always land in one cell; two points closer than ``step_mm`` can
    still fall either side of a cell wall, so ``step_mm`` should be far below the
    mesh's edge lengths.  Returns the repair (``vertex_source``: the lowest old
    index of each welded vertex) and ``vertex_of`` ``(n_old,)``, the new index of
    every old vertex (-1 for a non-finite one; its triangles are dropped).
    """
    n = mesh.n_vertices
    v = mesh.vertices
    finite = np.isfinite(v).all(axis=1)
    if n == 0 or not finite.any() or not step_mm > 0:
        return _unchanged(mesh), np.where(finite, np.arange(n), -1)
    lo = v[finite].min(axis=0)
    cells = np.floor((v[finite] - lo) / step_mm).astype(np.int64)
    side = cells.max(axis=0) + 1
    if float(side[0]) * float(side[1]) * float(side[2]) >= 2.0**62:  # keys would overflow
        raise ValueError(f"weld step {step_mm:g} mm is too fine for a mesh this large")
    key = (cells[:, 0] * side[1] + cells[:, 1]) * side[2] + cells[:, 2]
    _, inverse, _, first = unique_ints(key)
    rows = np.flatnonzero(finite)
    vertex_of = np.full(n, -1, np.int64)
    vertex_of[rows] = inverse
    faces = vertex_of[mesh.faces]
    faces = faces[(faces >= 0).all(axis=1)]
    source = rows[first]  # (the first occurrence is the lowest index)
    merged = n - len(source)
    if merged == 0 and finite.all():
        return _unchanged(mesh), np.arange(n)
    return (
        Repaired(
            Mesh(v[source], faces),
            source,
            f"welded {merged} coincident vertices (closer than {step_mm:.2g} mm)",
        ),
        vertex_of,
    )


def consistent_outward_winding(mesh: Mesh, tolerate: float = 1e-3) -> tuple[Repaired, np.ndarray]:
    """Wind every edge-connected piece consistently, its normals pointing away from the
    piece's centre; returns the repair and the ``(m,)`` mask of the turned triangles.

    Consistency: two triangles sharing an edge must run along it in opposite
    directions.  Solved at once for all pieces on the *double cover* of the
    triangle graph (each triangle as itself and turned over; a consistent pair
    joins same with same, an inconsistent one same with turned): the graph's
    connected components (scipy) put a triangle and its turned copy apart on an
    orientable piece, splitting it in two classes; the class of the larger area
    keeps its winding.  Only edges with exactly two triangles count (a non-manifold
    fin is left as it is), and a piece that cannot be wound one way
    (a Möbius-like tangle) is left as it is.  Up to ``tolerate`` (a fraction) of
    the manifold edges may disagree without a change: an iso-surface pinched where
    two sheets touch has a few such edges, and turning a patch there would not
    be a repair.  Outward is judged like
    :meth:`workbench.core.mesh.Mesh.outward`, per piece: area-weighted agreement
    of the face normals with the direction from the piece's centre.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = mesh.n_faces
    turned = np.zeros(m, bool)
    if m == 0:
        return _unchanged(mesh), turned
    f = mesh.faces
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=0)
    _, inverse, counts = mesh._unique_edges
    half = np.flatnonzero(counts[inverse] == 2)
    order = np.argsort(inverse[half], kind="stable")
    pair = half[order].reshape(-1, 2)  # the two half-edges of each manifold edge
    fa, fb = pair[:, 0] % m, pair[:, 1] % m
    # the same direction along the shared edge: the two triangles disagree
    flip = directed[pair[:, 0], 0] == directed[pair[:, 1], 0]
    piece = mesh.face_components
    if flip.sum() > tolerate * max(len(flip), 1):
        a = np.concatenate([fa, fa + m])
        b = np.concatenate([np.where(flip, fb + m, fb), np.where(flip, fb, fb + m)])
        graph = coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(2 * m, 2 * m))
        _, label = connected_components(graph, directed=False)
        # per piece, the class (triangles kept as they are) with the larger area wins
        mine, other = label[:m], label[m:]
        area = np.bincount(mine, np.nan_to_num(mesh.face_areas), len(label))
        turned = (mine != other) & (
            (area[mine] < area[other]) | ((area[mine] == area[other]) & (mine > other))
        )
    faces = np.where(turned[:, None], f[:, ::-1], f)
    # then outward, per piece
    tri = mesh.vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centres = tri.mean(axis=1)
    k = piece.max() + 1
    weight = np.bincount(piece, minlength=k).astype(float)
    mid = np.stack([np.bincount(piece, centres[:, i], k) for i in range(3)], axis=1)
    mid = mid / weight[:, None]
    agree = np.bincount(piece, np.einsum("ij,ij->i", cross, centres - mid[piece]), k)
    inward = (agree < 0)[piece]
    faces = np.where(inward[:, None], faces[:, ::-1], faces)
    said = []
    if turned.any():
        said.append(f"wound {int(turned.sum())} triangles like their neighbours")
    if inward.any():
        said.append(f"turned {int((agree < 0).sum())} inward-wound pieces outward")
    turned ^= inward
    if not turned.any():
        return _unchanged(mesh), turned
    return Repaired(Mesh(mesh.vertices, faces), np.arange(mesh.n_vertices), "; ".join(said)), turned
