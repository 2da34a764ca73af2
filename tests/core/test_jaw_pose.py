"""The mandible's pose on a skull whose cranium is in place: openings, shifts, pieces, occlusion."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.jaw_pose import (
    MAX_JOINT_SHIFT_MM,
    decompose,
    joint_loss,
    occlusion,
    pose_jaw,
)
from workbench.core.mesh import concatenate
from workbench.services.registration.jaw import axis_rotation


def _parts(head):
    cranium = concatenate([head.meshes["cranium"], head.meshes["upper_teeth"]])
    jaw = concatenate([head.meshes["mandible"], head.meshes["lower_teeth"]])
    return cranium, jaw


def _pose(head_target, head_ref, opening: float, shift=(0.0, 0.0, 0.0), with_jaw=True):
    """The target (female) skull with its jaw opened and shifted, posed against the
    reference (male) parts; the female's own jaw axis is where the jaw turns."""
    f_cranium, f_jaw = _parts(head_target)
    point, direction = head_target.tmj_axis
    m = axis_rotation(point, direction, np.radians(opening))
    m[:3, 3] += shift
    pieces = [f_cranium] + ([f_jaw.transformed(m)] if with_jaw else [])
    target = concatenate(pieces).outward()
    cranium, jaw = _parts(head_ref)
    found = pose_jaw(jaw, cranium, head_ref.tmj_axis, target, np.ones(target.n_vertices))
    return found, m


def test_decompose_reads_back_an_opening_and_a_shift(head_male):
    point, direction = head_male.tmj_axis
    m = axis_rotation(point, direction, np.radians(23.0))
    m[:3, 3] += [1.0, -2.0, 3.0]
    opening, shift = decompose(m, point, direction)
    assert opening == pytest.approx(23.0, abs=1e-9)
    assert np.allclose(shift, [1.0, -2.0, 3.0])
    assert joint_loss(np.zeros(3)) == 0.0 and 0.0 < joint_loss(np.array([0, 0, 4.0])) < 1.0


@pytest.mark.parametrize("opening", [0.0, 15.0, 32.0])
def test_an_opened_jaw_is_found_at_its_opening(head_female, head_male, opening):
    found, _ = _pose(head_female, head_male, opening)
    base, _ = _pose(head_female, head_male, 0.0) if opening else (found, None)
    assert found.present
    # the female jaw on the male reference: its opening relative to the closed female jaw
    assert found.opening_deg - base.opening_deg == pytest.approx(opening, abs=3.0)
    assert np.linalg.norm(found.shift_mm) < MAX_JOINT_SHIFT_MM


def test_a_jaw_pushed_forward_is_followed(head_female, head_male):
    base, _ = _pose(head_female, head_male, 0.0)
    pushed, _ = _pose(head_female, head_male, 10.0, shift=(0.0, 0.0, 5.0))
    assert pushed.present
    assert pushed.opening_deg - base.opening_deg == pytest.approx(10.0, abs=3.0)


def test_a_missing_jaw_is_not_found(head_female, head_male):
    found, _ = _pose(head_female, head_male, 0.0, with_jaw=False)
    assert not found.present
    assert found.bone_area < 0.25


def test_a_detached_jaw_is_matched_as_its_own_piece(head_female, head_male):
    """Opened 25° the female jaw no longer touches her cranium: one piece of the target
    holds the jaw's bone, and the jaw is matched to that piece alone."""
    found, _ = _pose(head_female, head_male, 25.0)
    assert found.present and found.piece


def test_occlusion_closes_to_contact_and_keeps_the_vertical_dimension_without_teeth(
    head_male,
):
    point, direction = head_male.tmj_axis
    upper = head_male.meshes["upper_teeth"].vertices
    lower = head_male.meshes["lower_teeth"].vertices
    opened = axis_rotation(point, direction, np.radians(20.0))

    class Found:  # a jaw found opened 20° on the reference's own skull
        matrix = opened
        opening_deg = 20.0

    lower_ct = lower @ opened[:3, :3].T + opened[:3, 3]
    closed = occlusion(Found(), head_male.tmj_axis, lower_ct, upper)  # type: ignore[arg-type]
    assert closed.method == "teeth in contact"
    # back to (about) the reference's own occlusion: the turn is small
    assert abs(closed.contact_turn_deg) <= 3.0
    back = lower_ct @ closed.matrix[:3, :3].T + closed.matrix[:3, 3]
    assert np.median(np.linalg.norm(back - lower, axis=1)) < 3.0
    toothless = occlusion(Found(), head_male.tmj_axis, None, None)  # type: ignore[arg-type]
    assert toothless.method == "reference vertical dimension, no teeth"
    assert np.allclose(toothless.matrix, np.linalg.inv(opened))
