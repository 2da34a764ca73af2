"""The midline-profile helpers of the snap rules (core.surface_patch), mm."""

from __future__ import annotations

import numpy as np

from tests.core._shapes import subdivided_octahedron
from workbench.core.mesh import Mesh
from workbench.core.surface_patch import PatchIndex, depth_below_upper_hull, front_profile


def _section() -> tuple[np.ndarray, np.ndarray, int]:
    """A nasal-root-like outer profile (a 3 mm dip at along = 0) with an inner wall 12 mm
    behind it, as a CT section through the frontal sinus has; the dip's index."""
    along = np.linspace(-15.0, 15.0, 61)
    outer = -3.0 * np.exp(-((along / 4.0) ** 2))
    inner = outer[10:50] - 12.0
    return np.concatenate([along, along[10:50]]), np.concatenate([outer, inner]), 30


def test_the_front_profile_keeps_the_outer_profile_and_its_deepest_point() -> None:
    along, height, dip = _section()
    front = front_profile(along, height)
    assert front.tolist() == list(range(61))  # the outer profile, in order
    # the whole section's deepest point is on the inner wall; the front profile's is the dip
    assert np.argmax(depth_below_upper_hull(along, height)) >= 61
    assert front[np.argmax(depth_below_upper_hull(along[front], height[front]))] == dip
    assert front_profile(np.zeros(0), np.zeros(0)).shape == (0,)


def test_points_behind_the_outer_wall_are_not_seen_from_the_front() -> None:
    # a 50 mm shell with a 30 mm cavity inside (an outer and an inner table)
    ball = subdivided_octahedron(4)
    outer = ball.vertices * 50.0
    inner = ball.vertices * 30.0
    faces = np.vstack([ball.faces, ball.faces[:, ::-1] + len(outer)])
    shell = Mesh(np.vstack([outer, inner]), faces)
    index = PatchIndex(shell)
    front = np.array([[0.0, 0.0, 50.0], [10.0, 0.0, np.sqrt(50.0**2 - 100.0)]])
    behind = np.array([[0.0, 0.0, 30.0], [0.0, 0.0, -50.0]])
    forward = np.array([0.0, 0.0, 1.0])
    assert index.seen_from(front, forward).all()
    assert not index.seen_from(behind, forward).any()
    assert index.seen_from(behind, -forward)[1]  # the back of the shell, seen from behind
