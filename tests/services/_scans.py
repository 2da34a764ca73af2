"""Damaged scans made from a reference head's skin (head frame, mm) for the scan-fit tests."""

from __future__ import annotations

import numpy as np

from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.template import TemplateHead

#: holes punched into the skin: (skin landmark at the centre, radius mm)
HOLES = (("chk_l", 12.0), ("g", 10.0))
MIRROR = np.diag([-1.0, 1.0, 1.0, 1.0])


def scan_pose(angles_deg: tuple[float, float, float] = (30.0, -50.0, 20.0)) -> np.ndarray:
    """A 4 x 4 rigid map head frame → an arbitrary scanner frame (mm)."""
    from scipy.spatial.transform import Rotation

    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("xyz", angles_deg, degrees=True).as_matrix()
    m[:3, 3] = (10.0, -300.0, 40.0)
    return m


def damaged_skin(
    head: TemplateHead, pose: np.ndarray | None = None, *, mirror: bool = False
) -> tuple[Mesh, LandmarkSet]:
    """``head``'s skin with two discs of triangles removed, mapped by ``pose`` (after a
    reflection of x when ``mirror``), and its skin landmarks in the same frame."""
    skin = head.skin
    at = head.skin_landmarks.as_dict()
    centres = skin.vertices[skin.faces].mean(axis=1)
    keep = np.ones(skin.n_faces, bool)
    for code, radius in HOLES:
        keep &= np.linalg.norm(centres - at[code], axis=1) > radius
    m = (scan_pose() if pose is None else pose) @ (MIRROR if mirror else np.eye(4))
    faces = skin.faces[keep]
    if mirror:
        faces = faces[:, ::-1]
    v = skin.vertices @ m[:3, :3].T + m[:3, 3]
    return Mesh(v, faces), head.skin_landmarks.transformed(m)
