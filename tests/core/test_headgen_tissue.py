"""The last step of the reference head: skin lifted to a minimum tissue over the bone (mm)."""

from __future__ import annotations

import numpy as np

from tests.core._shapes import subdivided_octahedron
from workbench.core.headgen.tissue import FALLOFF_MM, lift_skin_off_bone
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex

MIRROR = np.array([-1.0, 1.0, 1.0])
BUMP_AXIS = np.array([0.6, 0.0, 0.8])  # off the midline x = 0


def _skin_and_bone(bump_mm: float) -> tuple[Mesh, Mesh]:
    """A 45 mm sphere of skin over a 40 mm sphere of bone with a bump ``bump_mm`` high
    (about 7 mm wide) towards ``BUMP_AXIS``: at 4 mm the bone comes within 1 mm of the skin."""
    unit = subdivided_octahedron(5)
    skin = Mesh(unit.vertices * 45.0, unit.faces)
    ball = subdivided_octahedron(4)
    angle = np.arccos(np.clip(ball.vertices @ BUMP_AXIS, -1.0, 1.0))
    radius = 40.0 + bump_mm * np.exp(-((angle / 0.15) ** 2))
    return skin, Mesh(ball.vertices * radius[:, None], ball.faces)


def _partner(v: np.ndarray) -> np.ndarray:
    from scipy.spatial import cKDTree

    dist, partner = cKDTree(v).query(v * MIRROR)
    assert dist.max() < 1e-9
    return partner


def test_thin_skin_is_lifted_smoothly_and_the_rest_stays_bit_for_bit() -> None:
    skin, bone = _skin_and_bone(4.0)
    before = MeshIndex(bone).signed_distance(skin.vertices)
    assert before.min() < 1.1
    lifted = lift_skin_off_bone(skin, [bone], 2.0)
    after = MeshIndex(bone).signed_distance(lifted)
    assert after.min() >= 2.0 - 1e-6
    moved = np.linalg.norm(lifted - skin.vertices, axis=1)
    assert moved.max() < 1.2  # the deficit plus the margin, no more
    # only the bump's surroundings (and their mirror image) move; the rest is untouched
    near = np.minimum(
        np.linalg.norm(skin.vertices / 45.0 - BUMP_AXIS, axis=1),
        np.linalg.norm(skin.vertices / 45.0 - BUMP_AXIS * MIRROR, axis=1),
    )
    assert np.array_equal(lifted[near > 0.45], skin.vertices[near > 0.45])
    # a smooth lift (no step, no dent): it changes by at most ~0.3 mm per mm along the skin
    # (the bump (1 - (g/5)^2)^2 of a 1 mm lift is steepest at g = 2.9 mm: 0.31 mm/mm)
    e = np.concatenate([skin.faces[:, [0, 1]], skin.faces[:, [1, 2]], skin.faces[:, [2, 0]]])
    length = np.linalg.norm(skin.vertices[e[:, 0]] - skin.vertices[e[:, 1]], axis=1)
    assert (np.abs(moved[e[:, 0]] - moved[e[:, 1]]) / length).max() < 0.35
    # mirror-symmetric skin in, mirror-symmetric skin out
    partner = _partner(skin.vertices)
    np.testing.assert_allclose(lifted[partner] * MIRROR, lifted, atol=1e-12)


def test_held_vertices_do_not_move_and_enough_skin_is_left_alone() -> None:
    skin, bone = _skin_and_bone(4.0)
    top = int(np.argmax(skin.vertices @ BUMP_AXIS))  # the thinnest vertex
    partner = _partner(skin.vertices)
    held = [top, int(partner[top])]
    lifted = lift_skin_off_bone(skin, [bone], 2.0, held=held)
    np.testing.assert_array_equal(lifted[held], skin.vertices[held])
    after = MeshIndex(bone).signed_distance(lifted)
    far = np.linalg.norm(skin.vertices - skin.vertices[top], axis=1) > FALLOFF_MM + 3.0
    assert after[far].min() >= 2.0 - 1e-6
    # skin with the minimum everywhere comes back as it was
    skin, bone = _skin_and_bone(2.0)
    assert np.array_equal(lift_skin_off_bone(skin, [bone], 2.0), skin.vertices)
