"""Head frame and Frankfort Horizontal (workbench.core.frame).

A synthetic head is given in canonical head coordinates (x to the subject's
left, y up, z forward, FH = the plane y = 0, origin under the porion
midpoint on the midsagittal plane), moved by random rigid transforms, and
the frame must map it back.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from workbench.core.frame import RAS_TO_HEAD, apply_transform, frankfort_frame

# canonical landmarks (mm), head frame
PO_L, PO_R = np.array([70.0, 0.0, 0.0]), np.array([-70.0, 0.0, 0.0])
OR_L, OR_R = np.array([33.0, 0.0, 72.0]), np.array([-33.0, 0.0, 72.0])
NASION = np.array([0.0, 28.0, 90.0])
PROSTHION = np.array([0.0, -38.0, 84.0])
BASION = np.array([0.0, -22.0, 8.0])
OPISTHOCRANION = np.array([0.0, 45.0, -95.0])
MIDLINE = np.stack([NASION, PROSTHION, BASION, OPISTHOCRANION])


def rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


quaternions = (
    st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 4)
    .map(np.array)
    .filter(lambda q: np.linalg.norm(q) > 0.1)
)
translations = st.tuples(*[st.floats(-500, 500, allow_nan=False)] * 3).map(np.array)


def rigid(q: np.ndarray, t: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation(q)
    m[:3, 3] = t
    return m


def frame_for(m: np.ndarray, midline: bool = True, mirrored: bool = False, **kw):
    move = (
        (lambda p: apply_transform(m, p * np.array([-1.0, 1.0, 1.0])))
        if mirrored
        else (lambda p: apply_transform(m, p))
    )
    return frankfort_frame(
        move(PO_L),
        move(PO_R),
        move(OR_L),
        move(OR_R),
        midline=move(MIDLINE) if midline else None,
        above=[move(NASION), move(OPISTHOCRANION)],
        below=[move(PROSTHION)],
        **kw,
    ), move


@settings(max_examples=60, deadline=None)
@given(q=quaternions, t=translations, midline=st.booleans())
def test_rigidly_moved_head_maps_back_to_canonical_coordinates(q, t, midline):
    m = rigid(q, t)
    frame, move = frame_for(m, midline=midline)
    landmarks = np.stack([PO_L, PO_R, OR_L, OR_R, *MIDLINE])
    np.testing.assert_allclose(frame.to_head(move(landmarks)), landmarks, atol=1e-9)
    # midline landmarks lie on x = 0, the FH landmarks on y = 0
    np.testing.assert_allclose(frame.to_head(move(MIDLINE))[:, 0], 0.0, atol=1e-9)
    np.testing.assert_allclose(
        frame.to_head(move(np.stack([PO_L, PO_R, OR_L, OR_R])))[:, 1], 0.0, atol=1e-9
    )
    assert not frame.mirrored_input
    assert frame.fh_residual_mm < 1e-9


@settings(max_examples=60, deadline=None)
@given(
    q=quaternions,
    t=translations,
    pts=st.lists(st.tuples(*[st.floats(-300, 300, allow_nan=False)] * 3), min_size=1, max_size=20),
)
def test_round_trip_and_right_handed_rotation(q, t, pts):
    frame, _ = frame_for(rigid(q, t))
    r = frame.input_to_head[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(r) - 1.0) < 1e-12
    x, y, z = r  # head axes in input coordinates: z = x × y
    np.testing.assert_allclose(np.cross(x, y), z, atol=1e-12)
    p = np.array(pts, float)
    np.testing.assert_allclose(frame.to_input(frame.to_head(p)), p, atol=1e-9)
    np.testing.assert_allclose(frame.head_to_input @ frame.input_to_head, np.eye(4), atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(q=quaternions, t=translations)
def test_mirrored_input_is_flagged(q, t):
    frame, move = frame_for(rigid(q, t), mirrored=True)
    assert frame.mirrored_input
    # still a proper rotation: the frame is never a reflection
    assert abs(np.linalg.det(frame.input_to_head[:3, :3]) - 1.0) < 1e-12


def test_axes_point_left_up_forward():
    frame, move = frame_for(np.eye(4))
    np.testing.assert_allclose(frame.input_to_head, np.eye(4), atol=1e-12)
    # the head frame is (Left, Superior, Anterior): RAS maps with x = -R
    np.testing.assert_allclose(
        apply_transform(RAS_TO_HEAD, [[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
        [[-1, 0, 0], [0, 0, 1], [0, 1, 0]],
    )
    assert np.linalg.det(RAS_TO_HEAD[:3, :3]) == pytest.approx(1.0)


def test_three_landmark_frankfort_and_residual():
    frame = frankfort_frame(PO_L, PO_R, OR_L)
    np.testing.assert_allclose(frame.to_head(np.stack([PO_L, PO_R, OR_L]))[:, 1], 0.0, atol=1e-12)
    assert frame.fh_residual_mm == 0.0
    # a right orbitale 2 mm too low: the four-point fit spreads the error
    low = frankfort_frame(PO_L, PO_R, OR_L, OR_R - [0.0, 2.0, 0.0])
    assert 0.2 < low.fh_residual_mm < 1.0


def test_midline_accepts_arrays_and_two_points():
    frame = frankfort_frame(PO_L, PO_R, OR_L, OR_R, midline=MIDLINE[:2])
    np.testing.assert_allclose(frame.to_head(MIDLINE)[:, 0], 0.0, atol=1e-12)
    frame = frankfort_frame(
        PO_L,
        PO_R,
        OR_L,
        OR_R,
        midline=np.empty((0, 3)),
        above=np.array([NASION]),
        below=np.array([PROSTHION]),
    )
    assert not frame.mirrored_input


def test_bad_landmarks_are_refused():
    with pytest.raises(ValueError):
        frankfort_frame(PO_L, PO_L, OR_L)
    with pytest.raises(ValueError):
        frankfort_frame(PO_L, PO_R, [np.nan, 0.0, 0.0])
