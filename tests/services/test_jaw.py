"""The mandible of the reference head rotates about the temporomandibular axis."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.spatial import MeshIndex
from workbench.services.registration.jaw import axis_rotation, open_jaw


@pytest.fixture(scope="module")
def head(head_female):
    return head_female


def test_axis_rotation_keeps_the_axis_and_is_rigid() -> None:
    m = axis_rotation(np.array([1.0, 2.0, 3.0]), np.array([1.0, 0.0, 0.0]), 0.3)
    assert np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3))
    for t in (-5.0, 0.0, 7.0):
        p = np.array([1.0 + t, 2.0, 3.0])
        assert np.allclose(m[:3, :3] @ p + m[:3, 3], p)


def test_opening_moves_the_chin_down_and_back_and_closing_restores(head) -> None:
    me = head.skull_landmarks["me"].position
    opened = open_jaw(head, 20.0)
    me_open = opened.skull_landmarks["me"].position
    assert me_open[1] < me[1] - 10 and me_open[2] < me[2]  # down and back
    # cranial landmarks and the cranium do not move
    assert np.array_equal(opened.skull_landmarks["n"].position, head.skull_landmarks["n"].position)
    assert opened.meshes["cranium"] is head.meshes["cranium"]
    # the mouth opens: lower incisors move away from the upper ones
    gap = (
        MeshIndex(opened.meshes["upper_teeth"])
        .closest_points(opened.meshes["lower_teeth"].vertices)
        .distances.min()
    )
    assert gap > 5.0
    closed = open_jaw(opened, -20.0)
    assert np.allclose(
        closed.meshes["mandible"].vertices, head.meshes["mandible"].vertices, atol=1e-9
    )
    assert closed.provenance["jaw_angle_deg"] == 0.0
