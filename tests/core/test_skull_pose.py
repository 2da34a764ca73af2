"""Orientation of a bone surface from the bone alone: file axes, mirror, jaw, scoring both ways."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from workbench.core.mesh import Mesh, concatenate
from workbench.core.rigid_search import _angle_deg
from workbench.core.skull_pose import (
    canonical_frame,
    face_mask,
    search_skull_pose,
    swept_jaw,
    two_way_icp,
)


def _parts(head):
    cranium = concatenate([head.meshes["cranium"], head.meshes["upper_teeth"]])
    jaw = concatenate([head.meshes["mandible"], head.meshes["lower_teeth"]])
    return cranium, jaw


def _moved(mesh: Mesh, seed: int, mirror: bool = False) -> tuple[Mesh, np.ndarray]:
    m = np.eye(4)
    m[:3, :3] = Rotation.random(random_state=seed).as_matrix()
    m[:3, 3] = np.random.default_rng(seed).uniform(-300, 300, 3)
    if mirror:
        m[0] *= -1.0
    return mesh.transformed(m), m


def test_canonical_frame_turns_with_the_points():
    pts = np.random.default_rng(0).standard_normal((500, 3)) * [40.0, 25.0, 10.0]
    pts[:, 0] += 0.3 * pts[:, 0] ** 2 / 40.0  # skewed, so the signs are decided
    pts[:, 1] += 0.3 * pts[:, 1] ** 2 / 25.0
    m = np.eye(4)
    m[:3, :3] = Rotation.random(random_state=3).as_matrix()
    m[:3, 3] = [10.0, -20.0, 300.0]
    a = canonical_frame(pts)
    b = canonical_frame(pts @ m[:3, :3].T + m[:3, 3])
    assert np.allclose(a, b @ m, atol=1e-9)  # the same canonical coordinates
    assert np.isclose(np.linalg.det(a[:3, :3]), 1.0)


def test_the_female_skull_in_any_file_axes_is_oriented_alike(head_female, head_male):
    """The search's result does not depend on the file's axes: every turned copy lands on
    the same pose (to numerical noise), and that pose is the skull's own (identity)."""
    cranium, jaw = _parts(head_male)
    skull = concatenate(_parts(head_female))
    poses = []
    for seed in (0, 1, 2):
        moved, m = _moved(skull, seed)
        found = search_skull_pose(moved, cranium, jaw, head_male.tmj_axis)
        poses.append(found.best.matrix @ m)  # back to the skull's own axes
    for p in poses:
        scale = abs(np.linalg.det(p[:3, :3])) ** (1 / 3)
        assert _angle_deg(p[:3, :3] / scale, np.eye(3)) < 3.0
        assert np.linalg.norm(p[:3, 3]) < 5.0
    for p in poses[1:]:
        assert np.abs(p - poses[0]).max() < 1e-3


def test_a_mirrored_file_keeps_its_handedness_and_still_finds_the_face(head_female, head_male):
    cranium, jaw = _parts(head_male)
    skull = concatenate(_parts(head_female))
    moved, m = _moved(skull, 7, mirror=True)
    found = search_skull_pose(moved, cranium, jaw, head_male.tmj_axis)
    assert not found.mirrored
    assert np.linalg.det(found.best.matrix[:3, :3]) > 0  # a proper pose of the mirror image
    # the glabella of the moved skull lands on the reference's glabella
    g = head_female.skull_landmarks.as_dict()["g"]
    g_moved = m[:3, :3] @ g + m[:3, 3]
    g_found = found.best.matrix[:3, :3] @ g_moved + found.best.matrix[:3, 3]
    assert np.linalg.norm(g_found - head_male.skull_landmarks.as_dict()["g"]) < 6.0


def test_an_open_jaw_and_a_missing_jaw_do_not_tip_the_cranium(head_female, head_male):
    from workbench.services.registration.jaw import axis_rotation

    cranium, jaw = _parts(head_male)
    f_cranium, f_jaw = _parts(head_female)
    point, direction = head_female.tmj_axis
    opened = f_jaw.transformed(axis_rotation(point, direction, np.radians(30.0)))
    for skull in (concatenate([f_cranium, opened]), f_cranium):
        moved, m = _moved(skull, 11)
        found = search_skull_pose(moved, cranium, jaw, head_male.tmj_axis)
        p = found.best.matrix @ m
        scale = abs(np.linalg.det(p[:3, :3])) ** (1 / 3)
        assert _angle_deg(p[:3, :3] / scale, np.eye(3)) < 4.0


def test_a_hint_gives_the_rotation_and_the_same_refinement(head_female, head_male):
    cranium, jaw = _parts(head_male)
    skull = concatenate(_parts(head_female))
    moved, m = _moved(skull, 5)
    r = m[:3, :3]
    hint = (r @ [0.0, 0.0, 1.0], r @ [0.0, 1.0, 0.0], r @ [1.0, 0.0, 0.0])
    hinted = search_skull_pose(moved, cranium, jaw, head_male.tmj_axis, hint=hint)
    searched = search_skull_pose(moved, cranium, jaw, head_male.tmj_axis)
    assert hinted.hinted_handedness
    a, b = hinted.best.matrix, searched.best.matrix
    assert _angle_deg(a[:3, :3], b[:3, :3]) < 1.0
    c = moved.vertices.mean(axis=0)  # where each puts the skull's centre
    assert np.linalg.norm((a[:3, :3] - b[:3, :3]) @ c + a[:3, 3] - b[:3, 3]) < 2.0


def test_the_swept_jaw_holds_every_opening_and_the_face_mask_the_facial_skeleton(head_male):
    _, jaw = _parts(head_male)
    swept = swept_jaw(jaw, *head_male.tmj_axis)
    assert swept.n_vertices == 5 * jaw.n_vertices
    chin_low = swept.vertices[:, 1].min()
    assert chin_low < jaw.vertices[:, 1].min() - 10.0  # opened chins reach lower
    lms = head_male.skull_landmarks.as_dict()
    inside = face_mask(np.array([lms[c] for c in ("n", "or_l", "ec_r", "ans", "pr")]))
    outside = face_mask(np.array([lms[c] for c in ("v", "op", "po_l", "ba")]))
    assert inside.all() and not outside.any()


def test_two_way_icp_converges_to_one_pose_from_nearby_starts(head_female, head_male):
    """Starts a few degrees apart end within 0.5° of each other: each width is iterated to
    convergence, so the result does not depend on where a flat objective was entered."""
    from workbench.core.rigid_search import _Cloud, surface_samples
    from workbench.core.skull_pose import _TwoWay

    cranium, _ = _parts(head_male)
    rng = np.random.default_rng(0)
    ref = surface_samples(cranium, 6000, rng)
    face = _Cloud(ref.points[face_mask(ref.points)], ref.normals[face_mask(ref.points)])
    target = surface_samples(_parts(head_female)[0], 1500, rng)
    match = _TwoWay(ref, face, target)
    ends = []
    for deg in (-6.0, 0.0, 6.0):
        r = Rotation.from_euler("x", deg, degrees=True).as_matrix()
        lin, t = two_way_icp(match, r, np.array([2.0, -3.0, 1.0]))
        ends.append(lin / abs(np.linalg.det(lin)) ** (1 / 3))
    for e in ends[1:]:
        assert _angle_deg(e, ends[0]) < 0.5


@pytest.mark.parametrize("bad", ["maybe", "auto"])
def test_mirror_must_be_yes_or_no(head_male, bad):
    cranium, jaw = _parts(head_male)
    with pytest.raises(ValueError, match="mirror"):
        search_skull_pose(cranium, cranium, jaw, head_male.tmj_axis, mirror=bad)
