"""The reference face laid on a bust by the face alone (a crown wider than the head above it)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.services._scans import crowned_bust
from workbench.core.face_pose import place_face
from workbench.core.rigid_search import SCALE_RANGE
from workbench.core.spatial import MeshIndex
from workbench.services.templates.regions import face_regions


@pytest.fixture(scope="module")
def bust(head_female):
    return crowned_bust(head_female)


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


def test_matches_at_a_closest_vertex_do_not_depend_on_which_face_the_tree_returns():
    """At a closest vertex (a tie between its faces) the cosine is the vertex's pseudo-normal
    against the query normal, whichever face the search returned; the numpy-built and the
    compiled tree lay their leaves out differently and must give the same matches."""
    from workbench.core.bvh import LeafTree
    from workbench.core.face_pose import _Face
    from workbench.core.mesh import Mesh

    # a pyramid: its apex is shared by four faces of very different normals
    v = np.array([[0, 0, 10.0], [-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]])
    f = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [1, 4, 3], [1, 3, 2]])
    mesh = Mesh(v, f)
    points = np.array([[0.0, 0.0, 15.0], [0.1, -0.1, 14.0]])  # closest point: the apex
    normals = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    fast, slow = MeshIndex(mesh), MeshIndex(mesh)
    slow._tree = LeafTree(mesh, compiled=False)
    got = [_Face(points, normals, index).match(np.eye(4), np.arange(2)) for index in (fast, slow)]
    np.testing.assert_allclose(got[0][0], [v[0], v[0]], atol=1e-12)
    np.testing.assert_allclose(got[0][2], got[1][2], atol=1e-12)
    # the apex's angle-weighted normal is +z by symmetry: cos 1 (a side face's is ~0.7)
    np.testing.assert_allclose(got[0][2], 1.0, atol=1e-9)
