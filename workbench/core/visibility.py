"""Which surface points a range scanner could see: not buried in a cavity of the mesh.

A CT's skin iso-surface is closed around the airway, the mouth and the
nostrils; a photogrammetry mesh may hold the inside of the ear canal or
the oral cavity between parted lips.  A scanner looking at the head from
outside never records these walls, and the reference head has no such
surfaces to fit them with (its lips are closed, its nostrils end a few
millimetres in).  A point is *seen from outside* when at least one ray in
a cone around its outward normal leaves the mesh without hitting it
again (:data:`MIN_FREE_RAYS` of them); a wall inside a cavity has every
such ray blocked by the opposite wall.

Units: mm (any frame; only distances along rays are used).
"""

from __future__ import annotations

import numpy as np

from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.core.raycast import RayCaster

#: rays start this far out along the normal, so they do not hit their own triangles
RAY_OFFSET_MM = 0.3
#: half-angle of the cone of rays around the normal (degrees)
CONE_DEG = 35.0
#: rays tilted around the normal, besides the normal itself
CONE_RAYS = 6
#: a vertex is seen when at least this many of its rays leave freely: one free ray may
#: be the way out of a cavity through an open end of the mesh (the neck of a CT skin cut
#: by the field of view), not a line of sight of a scanner
MIN_FREE_RAYS = 2
#: hits farther than this do not block (a head is smaller; a table or wall far behind is not
#: a cavity)
MAX_BLOCK_MM = 250.0


def _cone(
    normals: np.ndarray, half_angle_deg: float, count: int, toward: np.ndarray | None = None
) -> np.ndarray:
    """(n, count + 1, 3) unit directions: the normal and ``count`` tilted around it, the
    first tilted toward ``toward`` (per point, any vector not along the normal)."""
    n = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    # a fixed axis not parallel to n where no (usable) direction is given
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(np.cross(n, helper), n)
    if toward is not None:
        along = toward - np.einsum("ij,ij->i", toward, n)[:, None] * n
        size = np.linalg.norm(along, axis=1, keepdims=True)
        t1 = np.where(size > 1e-6 * np.linalg.norm(toward, axis=1, keepdims=True), along, t1)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    a = np.radians(half_angle_deg)
    phi = 2 * np.pi * np.arange(count) / max(count, 1)
    tilted = (
        np.cos(a) * n[:, None, :]
        + np.sin(a) * np.cos(phi)[None, :, None] * t1[:, None, :]
        + np.sin(a) * np.sin(phi)[None, :, None] * t2[:, None, :]
    )
    return np.concatenate([n[:, None, :], tilted], axis=1)


def seen_from_outside(
    mesh: Mesh,
    *,
    normals: np.ndarray | None = None,
    cone_deg: float = CONE_DEG,
    rays: int = CONE_RAYS,
    max_block_mm: float = MAX_BLOCK_MM,
    min_free: int = MIN_FREE_RAYS,
) -> np.ndarray:
    """``(n_vertices,)`` bool: the vertex is visible from outside the mesh along ``min_free``
    of its rays (the normal and ``rays`` around it, ``cone_deg`` off it).

    ``normals`` (outward, per vertex) default to the area-weighted vertex
    normals, so the mesh must be wound outward.  A ray blocks only when it
    hits the mesh within ``max_block_mm``; isolated vertices count as seen.
    """
    nrm = vertex_normals(mesh) if normals is None else np.asarray(normals, float)
    used = np.linalg.norm(nrm, axis=1) > 0.5
    seen = np.ones(mesh.n_vertices, bool)
    if mesh.n_faces == 0 or not used.any():
        return seen
    ids = np.flatnonzero(used)
    # the cone's turn about the normal follows the surface (toward a neighbour of each
    # vertex), not the file's axes: which vertices are seen is then the same in any frame
    # (a fixed helper axis made 0.1-1 % of a CT skin's vertices change with a rotation)
    # (the lower-numbered other corner of the first face using it: the same whichever
    # way the faces are wound)
    corner, first = np.unique(mesh.faces.ravel(), return_index=True)
    row = mesh.faces[first // 3]
    neighbour = np.zeros(mesh.n_vertices, np.int64)
    neighbour[corner] = np.where(row == corner[:, None], np.iinfo(np.int64).max, row).min(axis=1)
    toward = mesh.vertices[neighbour[ids]] - mesh.vertices[ids]
    dirs = _cone(nrm[ids], cone_deg, rays, toward)  # (k, r, 3)
    caster = RayCaster.shared(mesh)
    free = np.zeros(dirs.shape[:2], bool)
    # the first min_free rays of every vertex, then the rest only where those were not
    # all free (most of a head's outer surface is decided by the first rays)
    todo = np.arange(len(ids))
    for j in range(dirs.shape[1]):
        if j >= min_free:
            todo = todo[free[todo].sum(axis=1) < min_free]
            if not len(todo):
                break
        origins = mesh.vertices[ids[todo]] + RAY_OFFSET_MM * dirs[todo, 0]
        hits = caster.first_hits(origins, dirs[todo, j], max_distance=max_block_mm)
        free[todo, j] = ~hits.hit
    seen[ids] = free.sum(axis=1) >= min_free
    return seen


#: a cap face has its three corners this close (mm) to a side of the bounding box ...
#: (a CT's lid sits exactly on a voxel plane; a rounded surface touching the box does not)
CAP_TOLERANCE_MM = 0.1
#: ... and faces out of that side (|cos| of its normal and the side's axis) ...
CAP_COS = 0.95
#: ... and the lid on that side covers at least this area (mm²)
MIN_CAP_AREA_MM2 = 200.0


def field_of_view_caps(mesh: Mesh) -> np.ndarray:
    """``(n_vertices,)`` bool: vertices of flat lids on the sides of the mesh's bounding box.

    A CT's iso-surface is closed where the body leaves the scanned volume
    (below the chin, at a cut vault): a flat lid exactly on a side of the
    volume, facing out of it.  That lid is where the field of view ended,
    not skin.  Only the box of the mesh in *its own* coordinates (the file's,
    where a CT's volume sides are axis-aligned) is meaningful, so call this on
    the mesh as read.
    """
    caps = np.zeros(mesh.n_vertices, bool)
    if mesh.n_faces == 0:
        return caps
    corners = mesh.vertices[mesh.faces]  # (m, 3, 3)
    used = mesh.vertices[np.bincount(mesh.faces.ravel(), minlength=mesh.n_vertices) > 0]
    lo, hi = used.min(axis=0), used.max(axis=0)
    fn, area = mesh.face_normals, mesh.face_areas
    for axis in range(3):
        facing = np.abs(fn[:, axis]) > CAP_COS
        for plane in (lo[axis], hi[axis]):
            lid = facing & (np.abs(corners[:, :, axis] - plane) <= CAP_TOLERANCE_MM).all(axis=1)
            if area[lid].sum() >= MIN_CAP_AREA_MM2:
                caps[mesh.faces[lid].ravel()] = True
    return caps
