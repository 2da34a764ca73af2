"""Orientation search: any file axes, a missing part, extra anatomy, seeds, hints, mirrors."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.mesh import Mesh, concatenate
from workbench.core.rigid_search import hint_rotation, search_pose
from workbench.services.templates.reference_parts import skull_surface


def _rot(seed: int) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    return q * np.sign(np.linalg.det(q))


def _error_mm(found: np.ndarray, truth: np.ndarray, pts: np.ndarray) -> float:
    a = pts @ found[:3, :3].T + found[:3, 3]
    b = pts @ truth[:3, :3].T + truth[:3, 3]
    return float(np.percentile(np.linalg.norm(a - b, axis=1), 90))


@pytest.fixture(scope="module")
def skulls(head_female, head_male):
    return skull_surface(head_female), skull_surface(head_male)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_any_file_axes(skulls, seed):
    target, reference = skulls
    r = _rot(seed)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, [40.0, -300.0, 900.0]
    moved = target.transformed(m)
    pose = search_pose(moved, reference)
    truth = np.linalg.inv(m)  # the female skull is in the same head frame as the reference
    assert _error_mm(pose.matrix, truth, moved.vertices[::40]) < 8.0
    assert pose.handedness == "assumed" and not pose.mirrored


def test_a_cranium_without_mandible_with_a_spine_below(skulls, head_female):
    from tests.core._shapes import subdivided_octahedron

    _, reference = skulls
    cranium = concatenate([head_female.meshes["cranium"], head_female.meshes["upper_teeth"]])
    s = subdivided_octahedron(3)
    spine = Mesh(s.vertices * [10.0, 35.0, 10.0] + [0.0, -95.0, -35.0], s.faces)
    target = concatenate([cranium, spine])
    m = np.eye(4)
    m[:3, :3] = _rot(7)
    pose = search_pose(target.transformed(m), reference)
    truth = np.linalg.inv(m)
    assert _error_mm(pose.matrix, truth, target.transformed(m).vertices[::40]) < 8.0


def test_hint_and_its_left_decide_the_handedness(skulls):
    target, reference = skulls
    mirrored = Mesh(target.vertices * [-1, 1, 1], target.faces[:, ::-1])
    pose = search_pose(mirrored, reference, hint=((0, 0, 1), (0, 1, 0), (-1, 0, 0)))
    assert pose.mirrored and pose.handedness == "hint"
    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    assert _error_mm(pose.matrix, flip, mirrored.vertices[::40]) < 6.0
    r, mirror = hint_rotation((0, 0, 1), (0, 1, 0), (1, 0, 0))
    assert not mirror and np.allclose(r, np.eye(3))


def test_seeds_give_a_mirrored_file_away(skulls, head_female, head_male):
    target, reference = skulls
    mirrored = Mesh(target.vertices * [-1, 1, 1], target.faces[:, ::-1])
    ref = head_male.skull_landmarks.as_dict()
    own = head_female.skull_landmarks.as_dict()
    codes = ["po_l", "po_r", "or_l", "zy_r", "go_l", "n", "pg"]
    seeds = (np.array([own[c] * [-1, 1, 1] for c in codes]), np.array([ref[c] for c in codes]))
    pose = search_pose(mirrored, reference, seeds=seeds)
    assert pose.mirrored and pose.handedness == "seeds" and pose.method == "seeds"
    assert 0.85 < pose.scale < 1.15
