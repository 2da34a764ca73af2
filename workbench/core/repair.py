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
