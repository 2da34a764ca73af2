"""The reference face laid on a bust by the face alone (a crown and a plinth around it)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.face_pose import place_face
from workbench.core.mesh import Mesh, concatenate
from workbench.core.rigid_search import SCALE_RANGE
from workbench.core.spatial import MeshIndex
from workbench.services.compare import face_regions


def _cylinder(centre_xz, radius: float, y0: float, y1: float, n: int = 72, rings: int = 16) -> Mesh:
    """A closed upright cylinder, wound outward (side normals radial, caps up and down), mm."""
    a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    ys = np.linspace(y0, y1, rings)
    ring = np.stack([radius * np.sin(a), np.zeros(n), radius * np.cos(a)], axis=1)
    v = [ring + (centre_xz[0], y, centre_xz[1]) for y in ys]
    v = np.vstack(v + [[(centre_xz[0], y0, centre_xz[1]), (centre_xz[0], y1, centre_xz[1])]])
    faces = []
    for r in range(rings - 1):
        for i in range(n):
            j = (i + 1) % n
            a0, a1, b0, b1 = r * n + i, r * n + j, (r + 1) * n + i, (r + 1) * n + j
            faces += [(a0, a1, b1), (a0, b1, b0)]
    bottom, top = len(v) - 2, len(v) - 1
    for i in range(n):
        j = (i + 1) % n
        faces.append((bottom, j, i))
        faces.append((top, (rings - 1) * n + i, (rings - 1) * n + j))
    return Mesh(v, np.array(faces))


@pytest.fixture(scope="module")
def bust(head_female):
    """The female skin below the brow under a tall crown wider than the head, on a plinth."""
    skin = head_female.skin
    at = head_female.skin_landmarks.as_dict()
    brow = at["g"][1] + 8.0
    centres = skin.vertices[skin.faces].mean(axis=1)
    keep = (centres[:, 1] < brow) & (centres[:, 1] > at["gn"][1] - 60.0)
    face = Mesh(skin.vertices, skin.faces[keep])
    head_z = float(np.median(skin.vertices[:, 2]))
    half_width = float(np.ptp(skin.vertices[:, 0])) / 2
    crown = _cylinder((0.0, head_z - 15.0), 1.3 * half_width, brow - 4.0, brow + 170.0)
    plinth = _cylinder(
        (0.0, head_z - 10.0), 2.2 * half_width, at["gn"][1] - 160.0, at["gn"][1] - 60.0
    )
    return concatenate([face, crown, plinth]), at


def test_a_face_shifted_and_resized_is_found_again(bust, head_male):
    scan, truth = bust
    ids = np.concatenate(list(face_regions(head_male).values()))
    # a start like the one a pose scored over the whole bust gave Nefertiti: the reference
    # face laid 60 mm too high (on the crown) and 15 % too small
    start = np.eye(4)
    start[:3, :3] *= 1.15
    start[:3, 3] = (0.0, -60.0, 0.0)
    placed = place_face(
        MeshIndex(scan),
        head_male.skin.vertices[ids],
        head_male.skin.vertex_normals[ids],
        start,
        scale_range=SCALE_RANGE,
    )
    back = np.linalg.inv(placed.matrix)
    ref = head_male.skin_landmarks.as_dict()
    for code in ("prn", "sn", "pg", "n"):
        at = back[:3, :3] @ ref[code] + back[:3, 3]
        # the male reference on the female face: their shapes differ by a few mm
        assert np.linalg.norm(at - truth[code]) < 7.0, code
    assert placed.loss < 0.5 * placed.start_loss
    assert placed.matched_fraction > 0.5
    # the female face is smaller than the male reference's: 0.85-1.0 of it
    assert 0.85 < 1.0 / placed.scale < 1.02


def test_a_good_start_stays(bust, head_male):
    scan, truth = bust
    ids = np.concatenate(list(face_regions(head_male).values()))
    placed = place_face(
        MeshIndex(scan),
        head_male.skin.vertices[ids],
        head_male.skin.vertex_normals[ids],
        np.eye(4),
        scale_range=SCALE_RANGE,
    )
    back = np.linalg.inv(placed.matrix)
    at = back[:3, :3] @ head_male.skin_landmarks.as_dict()["prn"] + back[:3, 3]
    assert np.linalg.norm(at - truth["prn"]) < 7.0
    assert placed.loss <= placed.start_loss


def test_a_mirrored_start_keeps_its_handedness(bust, head_male):
    scan, _ = bust
    ids = np.concatenate(list(face_regions(head_male).values()))
    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    placed = place_face(
        MeshIndex(scan.transformed(flip)),
        head_male.skin.vertices[ids],
        head_male.skin.vertex_normals[ids],
        flip,
        scale_range=SCALE_RANGE,
    )
    assert np.linalg.det(placed.matrix[:3, :3]) < 0
    assert placed.loss < 0.3
