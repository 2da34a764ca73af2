"""Articulation of a registered skull: the jaw brought into occlusion (head frame, mm).

See :func:`articulate`; the registration itself is
:func:`workbench.services.registration.skull_registration.register_skull`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.jaw_pose import occlusion
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh, concatenate
from workbench.core.threads import query_workers
from workbench.model.template import TemplateHead
from workbench.services.registration.result import (
    OBSERVED_WEIGHT,
    SkullRegistration,
    apply_points,
)

#: a target vertex belongs to the jaw when the registered mandible (with its teeth) is nearer
#: to it than the registered cranium, and within this distance (mm)
JAW_BONE_MM = 8.0
#: target tooth points: bone this close to the registered teeth (mm), used when at least
#: TEETH_OBSERVED of the registered teeth's vertices were observed on bone
TEETH_MM = 6.0
TEETH_OBSERVED = 0.25


def articulate(reg: SkullRegistration, head: TemplateHead) -> SkullRegistration:
    """``reg`` with the jaw brought into occlusion (teeth together, condyles in the fossae).

    Practitioners articulate the mandible before they reconstruct; a CT comes
    with the mouth open, or the jaw pushed.  The jaw's bone (target vertices
    nearer the registered mandible than the cranium) and the registered
    mandible with its teeth are turned by
    :func:`workbench.core.jaw_pose.occlusion`: back through the jaw's found
    pose to the reference's closed relation, then about the condylar axis
    until the lower teeth meet the upper ones; a skull without teeth keeps the
    reference head's vertical dimension (its teeth in occlusion).  Triangles
    joining the jaw to the cranium (the joints, touching teeth) are left out
    of the articulated bone.  The mandible's landmarks move with it.
    Returns ``reg`` itself when no mandible was found.
    """
    if reg.jaw is None or not reg.jaw.present:
        return reg
    target = reg.target_h
    jaw_parts = ("mandible", "lower_teeth")
    lower_ref = concatenate([reg.meshes[p] for p in jaw_parts]).vertices
    upper_ref = concatenate([reg.meshes[p] for p in ("cranium", "upper_teeth")]).vertices
    # only bone within reach of the registered jaw can be the jaw's
    lo, hi = lower_ref.min(axis=0) - JAW_BONE_MM, lower_ref.max(axis=0) + JAW_BONE_MM
    near = np.flatnonzero(((target.vertices >= lo) & (target.vertices <= hi)).all(axis=1))
    pts = target.vertices[near]
    workers = query_workers(len(pts))
    d_jaw = cKDTree(lower_ref).query(pts, workers=workers)[0]
    d_cranium = cKDTree(upper_ref).query(pts, workers=workers)[0]
    on_jaw_bone = (d_jaw < d_cranium) & (d_jaw < JAW_BONE_MM)
    bone = np.zeros(target.n_vertices, bool)
    bone[near[on_jaw_bone]] = True
    teeth = [
        float(np.mean(reg.observed[p] > OBSERVED_WEIGHT)) for p in ("lower_teeth", "upper_teeth")
    ]
    lower = upper = None
    if min(teeth) >= TEETH_OBSERVED:
        near_lower = cKDTree(reg.meshes["lower_teeth"].vertices).query(pts, workers=workers)[0]
        near_upper = cKDTree(reg.meshes["upper_teeth"].vertices).query(pts, workers=workers)[0]
        lower = pts[on_jaw_bone & (near_lower < TEETH_MM)]
        upper = pts[~on_jaw_bone & (near_upper < TEETH_MM)]
    occ = occlusion(reg.jaw, reg.jaw_axis, lower, upper)
    m = occ.matrix
    moved_v = target.vertices.copy()
    moved_v[bone] = apply_points(m, moved_v[bone])
    labels = bone[target.faces]
    whole = labels.all(axis=1) | ~labels.any(axis=1)
    target_a = Mesh(moved_v, target.faces[whole])
    meshes = dict(reg.meshes)
    for p in jaw_parts:
        meshes[p] = reg.meshes[p].with_vertices(apply_points(m, reg.meshes[p].vertices))
    on_jaw = {c for c, part in head.skull_landmark_part.items() if part == "mandible"}
    inferred = {c: (apply_points(m, p)[0] if c in on_jaw else p) for c, p in reg.inferred.items()}
    to_input = np.linalg.inv(reg.input_to_head) @ m @ reg.input_to_head
    lms = tuple(
        lm.moved(apply_points(to_input, lm.position)[0], lm.status)
        if lm.code in on_jaw and lm.is_defined
        else lm
        for lm in reg.landmarks
    )
    figures = dict(reg.figures)
    figures["jaw"] = {
        **dict(figures.get("jaw", {})),
        "occlusion": {
            **occ.figures(),
            "opening_in_ct_deg": round(reg.jaw.opening_deg, 2),
            "jaw_bone_vertices": int(bone.sum()),
            "joining_triangles_left_out": int((~whole).sum()),
        },
    }
    return replace(
        reg,
        meshes=meshes,
        target_h=target_a,
        inferred=inferred,
        landmarks=LandmarkSet(reg.landmarks.surface, lms),
        figures=figures,
        occlusion=occ,
        jaw_bone=bone,
    )
