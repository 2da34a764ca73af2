"""Thin sheets of a scan that are not the face's skin: cords, straps, bands, hair, fins.

A CT's skin surface can hold a cord or strap over the face (the VHP CTs), a
holder's band across the chin (headsq), strands of hair or a segmentation
fin.  A scan vertex lies on such a sheet when the ray along its inward normal
leaves the scan's inside within :data:`~workbench.services.scan_fit.settings.SHEET_MAX_MM`
(:func:`_leave_inward`) and then either

* enters the scan again within :data:`~workbench.services.scan_fit.settings.SHEET_GAP_MM`
  (more of the scan beneath it, found before the fit: :func:`_sheets_over_scan`), or
* lies, with its exit point, wholly outside the fitted skin (after the fit:
  :func:`_sheets_outside`).

The fit matches no skin to such sheets and leaves them out of its figures.
Units mm; the scan in the head frame of the fitted person (x to the subject's
left, y up, z toward the face), wound outward.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.mesh import Mesh
from workbench.core.raycast import RayCaster
from workbench.core.spatial import MeshIndex
from workbench.services.scan_fit.settings import SHEET_GAP_MM, SHEET_MAX_MM, SHEET_OUTSIDE_MM


def _leave_inward(scan_h: Mesh, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of scan vertices ``rows``, those whose ray along the inward normal leaves the scan's
    inside (meets a back-facing triangle) within :data:`SHEET_MAX_MM`: a thin sheet.
    Returns their places in ``rows``, their inward directions and the exit points (head
    frame, mm; the scan wound outward)."""
    normals = scan_h.vertex_normals[rows]
    # (a vertex of no triangle, or of degenerate ones only, has no normal to follow)
    places = np.flatnonzero(np.abs(normals).sum(axis=1) > 0.5)
    inward = -normals[places]
    if not len(places):
        return places, inward, np.empty((0, 3))
    # (started a hair past the surface, so a ray does not meet the triangles it left)
    hits = RayCaster.shared(scan_h).first_hits(
        scan_h.vertices[rows[places]] + 0.05 * inward, inward, max_distance=SHEET_MAX_MM
    )
    facing = np.einsum("ij,ij->i", scan_h.face_normals[np.maximum(hits.face_ids, 0)], inward)
    leaves = hits.hit & (facing > 0)
    return places[leaves], inward[leaves], hits.points[leaves]


def _sheets_over_scan(
    scan_h: Mesh, candidates: np.ndarray, reference: Mesh, thin: np.ndarray
) -> np.ndarray:
    """Per scan vertex: does it lie on a thin sheet with more of the scan beneath it (head
    frame, mm; the scan wound outward, the ``reference`` skin placed on it)?

    Seeds: a ray from the vertex along its inward normal leaves the scan's inside
    within :data:`SHEET_MAX_MM` (:func:`_leave_inward`) and then enters it again
    within :data:`SHEET_GAP_MM`: a cord, strap or strand of hair over the skin.
    The whole sheet then goes with its seeds: every thin vertex joined to one by
    thin vertices (the cord's sides, whose rays run across it with nothing
    beneath).  Only among ``candidates``, and not where the nearest reference
    vertex is ``thin`` (its own thin parts, the alae over the nostrils:
    :data:`SHEET_PARTS`).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    out = np.zeros(scan_h.n_vertices, bool)
    rows = np.flatnonzero(candidates)
    places, inward, exits = _leave_inward(scan_h, rows)
    rows = rows[places]
    if len(rows) and thin.any():
        _, nearest = cKDTree(reference.vertices).query(scan_h.vertices[rows])
        keep = ~thin[nearest]
        rows, inward, exits = rows[keep], inward[keep], exits[keep]
    if not len(rows):
        return out
    hits = RayCaster.shared(scan_h).first_hits(
        exits + 0.05 * inward, inward, max_distance=SHEET_GAP_MM
    )
    facing = np.einsum("ij,ij->i", scan_h.face_normals[np.maximum(hits.face_ids, 0)], inward)
    seeds = hits.hit & (facing < 0)
    if not seeds.any():
        return out
    # the thin vertices' own graph: its pieces holding a seed
    slot = np.full(scan_h.n_vertices, -1)
    slot[rows] = np.arange(len(rows))
    e = slot[scan_h.edges_unique]
    e = e[(e >= 0).all(axis=1)]
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(rows), len(rows)))
    _, piece = connected_components(graph, directed=False)
    out[rows[np.isin(piece, piece[seeds])]] = True
    return out


def _sheets_outside(scan_h: Mesh, ids: np.ndarray, skin: MeshIndex) -> np.ndarray:
    """Per scan vertex ``ids``: does it lie on a thin sheet of the scan wholly outside the
    fitted skin (head frame, mm; the scan wound outward)?

    The vertex's inward ray leaves the scan within :data:`SHEET_MAX_MM`
    (:func:`_leave_inward`), and both the vertex and that exit point lie more
    than :data:`SHEET_OUTSIDE_MM` outside the fitted skin (signed by the
    closest feature's pseudo-normal): a fin, or a cord with nothing beneath
    it.  The alae and the lips at their slit are thin too, but their inner side
    lies inside the fitted skin.
    """
    out = np.zeros(len(ids), bool)
    if not len(ids):
        return out
    outside = np.flatnonzero(skin.signed_distance(scan_h.vertices[ids]) > SHEET_OUTSIDE_MM)
    places, _, exits = _leave_inward(scan_h, ids[outside])
    if len(places):
        out[outside[places]] = skin.signed_distance(exits) > SHEET_OUTSIDE_MM
    return out
