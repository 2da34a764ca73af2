"""Open or close the reference head's jaw: rotate the mandible about the TMJ axis.

Units and frame: mm, degrees at this interface, head frame (x to the
subject's left, y up, z forward).  The axis is the line through the two
condyle centres stored with the template (Kähler 2003, §7.3.1; MEDUSA uses
the same inter-condylar axis).  Positive angles open the mouth (the chin
moves down and back).  The mandible, the lower teeth, the tongue and every
skull landmark on the mandible move rigidly; the skin is not changed here
(its response to the jaw belongs to the animation model).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.model.template import TemplateHead

JAW_PARTS = ("mandible", "lower_teeth", "tongue")


def axis_rotation(point: np.ndarray, direction: np.ndarray, angle_rad: float) -> np.ndarray:
    """4x4 rigid rotation by ``angle_rad`` about the line ``point + t * direction`` (right-hand rule)."""
    k = np.asarray(direction, dtype=np.float64)
    k = k / np.linalg.norm(k)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    r = np.eye(3) + np.sin(angle_rad) * kx + (1.0 - np.cos(angle_rad)) * (kx @ kx)
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = np.asarray(point, float) - r @ np.asarray(point, float)
    return m


def open_jaw(head: TemplateHead, angle_deg: float) -> TemplateHead:
    """The head with the mandible rotated by ``angle_deg`` (positive opens the mouth).

    The template's axis direction points to the subject's left (+x); by the
    right-hand rule a positive rotation about +x turns +z (forward) toward
    -y (down), which is what opening the mouth does to the chin.
    """
    point, direction = head.tmj_axis
    m = axis_rotation(point, direction, np.deg2rad(angle_deg))
    meshes = dict(head.meshes)
    for part in JAW_PARTS:
        mesh = meshes[part]
        meshes[part] = mesh.with_vertices(mesh.vertices @ m[:3, :3].T + m[:3, 3])
    moved = []
    for lm in head.skull_landmarks:
        if lm.is_defined and head.skull_landmark_part.get(lm.code) == "mandible":
            p = m[:3, :3] @ lm.position + m[:3, 3]
            lm = Landmark(lm.code, p, lm.status, lm.confidence, lm.description)
        moved.append(lm)
    provenance = dict(head.provenance)
    provenance["jaw_angle_deg"] = float(provenance.get("jaw_angle_deg", 0.0)) + float(angle_deg)
    return replace(
        head,
        meshes=meshes,
        skull_landmarks=LandmarkSet(head.skull_landmarks.surface, tuple(moved)),
        provenance=provenance,
    )
