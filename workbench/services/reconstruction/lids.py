"""The lids rest on the eyeballs: skin a fit left inside a globe is moved out.

The fit places the eyeballs by a published rule (the corneal apex 16 mm in front of
ectoconchion, Stephan 2009) and carries the lids with them in its warp, but the
warp's other targets (dowels, guides) can leave lid skin inside a globe: on headsq's
face 96 skin vertices were, up to 1.7 mm behind the globe's surface and more where the
cornea bulges, and every portrait showed the eyeballs through the lids, wide and
bulging.  :func:`lids_on_globes` moves such skin out to :data:`GLOBE_CLEARANCE_MM`.

Units mm; any frame, the skin and the eyes in the same one (the fit's head frame).
"""

from __future__ import annotations

import numpy as np

from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex

#: the lids rest on the globe: skin closer to an eyeball (its cornea included) than this
#: is moved out along the globe's normal to it, and the skin around follows within
#: :data:`LID_SPREAD_MM` (a lid is ~1 mm of skin over the tarsal plate at the least)
GLOBE_CLEARANCE_MM = 1.0
LID_SPREAD_MM = 4.0


def lids_on_globes(
    vertices: np.ndarray, eyes: Mesh | None
) -> tuple[np.ndarray, dict[str, float | int]]:
    """Skin ``vertices`` (head frame, mm) with the lids resting on the eyeballs.

    A vertex closer to the eyes' surface (the globes with their corneas, closed meshes)
    than :data:`GLOBE_CLEARANCE_MM`, or inside it, is moved out along the surface's
    normal at its closest point to that clearance; vertices within
    :data:`LID_SPREAD_MM` of a moved one follow by a smooth fraction of the nearest
    moves, so the lid stays smooth.  Figures: how many vertices were inside a globe and
    were moved, and the largest move (mm).
    """
    v = np.asarray(vertices, float)
    none: dict[str, float | int] = {"skin_in_globes": 0, "lid_vertices_rested": 0}
    if eyes is None or eyes.n_faces == 0:
        return v, {**none, "max_lid_move_mm": 0.0}
    from scipy.spatial import cKDTree

    index = MeshIndex.shared(eyes)
    # every vertex that could be inside or near a globe: within a globe's radius (half
    # the eyes' smallest extent, one globe's diameter) of its surface
    reach = GLOBE_CLEARANCE_MM + 0.5 * float(np.min(eyes.extent))
    near = np.flatnonzero(cKDTree(eyes.vertices).query(v, distance_upper_bound=reach)[0] < np.inf)
    if not len(near):
        return v, {**none, "max_lid_move_mm": 0.0}
    found, signed = index.signed_closest_points(v[near])
    lack = GLOBE_CLEARANCE_MM - signed
    moved = lack > 0.0
    if not moved.any():
        return v, {**none, "max_lid_move_mm": 0.0}
    normals = index.pseudo_normals(found.face_ids, found.barycentric)
    ids = near[moved]
    push = lack[moved, None] * normals[moved]
    out = v.copy()
    # the skin around: each vertex within LID_SPREAD_MM takes the nearest moves, faded
    tree = cKDTree(v[ids])
    around = np.flatnonzero(tree.query(v, distance_upper_bound=LID_SPREAD_MM)[0] < np.inf)
    around = around[~np.isin(around, ids)]
    if len(around):
        dist, nearest = tree.query(v[around], k=min(4, len(ids)))
        dist, nearest = dist.reshape(len(around), -1), nearest.reshape(len(around), -1)
        weight = np.clip(1.0 - dist / LID_SPREAD_MM, 0.0, 1.0) ** 2
        share = weight / np.maximum(weight.sum(axis=1, keepdims=True), 1e-12)
        fade = weight.max(axis=1, keepdims=True)
        out[around] += fade * np.einsum("kj,kjd->kd", share, push[nearest])
    out[ids] += push
    figures: dict[str, float | int] = {
        "skin_in_globes": int((signed < 0.0).sum()),
        "lid_vertices_rested": int(len(ids)),
        "max_lid_move_mm": round(float(lack[moved].max()), 3),
    }
    return out, figures


__all__ = ["GLOBE_CLEARANCE_MM", "LID_SPREAD_MM", "lids_on_globes"]
