"""Landmark suggestion by alignment, regularised warp and projection (services.landmark_transfer)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.services.landmarks.frame import head_frame_from_landmarks
from workbench.services.landmarks.transfer import transfer_landmarks
from workbench.services.templates.reference_parts import skull_surface


def _rotation(deg: float, axis: np.ndarray) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    t = np.radians(deg)
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k


@pytest.fixture(scope="module")
def skull(head_male) -> Mesh:
    return skull_surface(head_male)


def test_recovers_landmarks_of_a_moved_scaled_skull(head_male, skull):
    rot = _rotation(70, [1, 2, 0.5])
    target = skull.with_vertices(skull.vertices @ rot.T * 1.08 + [40, -25, 300])
    truth = head_male.skull_landmarks.positions @ rot.T * 1.08 + [40, -25, 300]
    res = transfer_landmarks(
        target, skull, head_male.skull_landmarks, orientation=(rot @ [0, 0, 1], rot @ [0, 1, 0])
    )
    err = np.linalg.norm(res.landmarks.positions - truth, axis=1)
    assert all(lm.status == "suggested" for lm in res.landmarks)
    assert np.median(err) < 1.0 and err.max() < 4.0
    assert res.alignment.scale == pytest.approx(1 / 1.08, rel=0.02)


def test_seeds_align_without_a_hint_and_are_kept(head_male, skull):
    rot = _rotation(-120, [0.3, 1, 0.2])
    target = skull.with_vertices(skull.vertices @ rot.T - [10, 200, 5])
    lms = head_male.skull_landmarks
    seed_codes = ("n", "po_l", "po_r", "pr")
    seeds = LandmarkSet(
        "skull", tuple(lms[c].moved(lms[c].position @ rot.T - [10, 200, 5]) for c in seed_codes)
    )
    res = transfer_landmarks(target, skull, lms, seeds=seeds)
    assert res.alignment.method == "seeds"
    for c in seed_codes:
        assert res.landmarks[c].status == "placed"
        np.testing.assert_allclose(res.landmarks[c].position, seeds[c].position)
    truth = lms.positions @ rot.T - [10, 200, 5]
    assert np.median(np.linalg.norm(res.landmarks.positions - truth, axis=1)) < 1.0


def test_cut_vault_gives_absent_landmarks_not_floating_points(head_male, skull):
    # a CT field of view ending 30 mm above the Frankfort plane: no vertex, no bregma
    keep = (skull.vertices[skull.faces][:, :, 1] < 30.0).all(axis=1)
    cut = Mesh(skull.vertices, skull.faces[keep])
    res = transfer_landmarks(
        cut, skull, head_male.skull_landmarks, orientation=((0, 0, 1), (0, 1, 0))
    )
    for code in ("v", "b"):
        assert res.landmarks[code].status == "absent", code
    for code in ("n", "pr", "gn", "zy_l", "go_r", "po_l"):
        assert res.landmarks[code].status == "suggested", code
    defined = res.landmarks.defined()
    d = np.linalg.norm(
        defined.positions - head_male.skull_landmarks.positions_of(defined.codes), axis=1
    )
    assert np.median(d) < 1.5
    assert any("absent" in w for w in res.warnings)


def test_headsq_bone_frame_from_suggested_landmarks(
    head_male, skull, headsq_surfaces, headsq_orientation
):
    """Real CT: the suggested porions/orbitales give a Frankfort frame that
    agrees with the scan's known anatomical axes, and the cut-off vault is absent."""
    res = transfer_landmarks(
        headsq_surfaces["bone"], skull, head_male.skull_landmarks, orientation=headsq_orientation
    )
    lms = res.landmarks
    assert lms["v"].status == "absent" and lms["b"].status == "absent"
    assert sum(lm.status == "suggested" for lm in lms) >= 35
    frame = head_frame_from_landmarks(lms.defined())
    to_head = frame.input_to_head[:3, :3]
    anterior, superior, left = (np.asarray(v, float) for v in headsq_orientation)
    assert np.degrees(np.arccos(np.clip((to_head @ anterior)[2], -1, 1))) < 20
    assert (to_head @ left)[0] > 0.9
    # the NRRD space is left-handed: a proper rotation cannot also map
    # superior to up, and the frame says so instead of silently flipping
    assert frame.mirrored_input
    assert (to_head @ superior)[1] < -0.9
    # every suggested point lies on the bone surface
    from workbench.core.spatial import MeshIndex

    d = MeshIndex(headsq_surfaces["bone"]).closest_points(lms.defined().positions).distances
    assert d.max() < 1e-6


def test_seeds_on_a_mirrored_scan(head_male, skull):
    """A left-handed file (x flipped) with a few seeds: the reflection is found."""
    lms = head_male.skull_landmarks
    mirrored = Mesh(skull.vertices * [-1.0, 1.0, 1.0], skull.faces[:, ::-1])
    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    seeds = LandmarkSet(
        "skull",
        tuple(
            lms[c].moved(lms[c].position * [-1.0, 1.0, 1.0])
            for c in ("n", "po_l", "po_r", "pr", "go_l")
        ),
    )
    res = transfer_landmarks(mirrored, skull, lms, seeds=seeds)
    assert np.linalg.det(res.alignment.matrix[:3, :3]) < 0
    truth = lms.transformed(flip).positions
    assert np.median(np.linalg.norm(res.landmarks.positions - truth, axis=1)) < 1.0


def test_normals_at_landmarks_do_not_depend_on_the_order_of_the_triangles(skull):
    """A landmark on a vertex (every reference landmark that was snapped) or an edge has
    several faces at the same distance; which one the tree returns depends on the order
    of the triangles.  The normal used is the closest feature's, the same either way."""
    from workbench.services.landmarks.transfer import _normals_at

    order = np.random.default_rng(3).permutation(skull.n_faces)
    shuffled = Mesh(skull.vertices, skull.faces[order])
    edges = skull.vertices[skull.edges_unique[:2000]].mean(axis=1)
    points = np.vstack([skull.vertices[:2000], edges])
    a, b = _normals_at(skull, points), _normals_at(shuffled, points)
    assert np.abs(a - b).max() < 1e-9
    assert np.allclose(np.linalg.norm(a, axis=1), 1.0)
