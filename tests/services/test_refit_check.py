"""An edit must not break the face: a refit that turns the head, moves the face away from
the edit, or makes the registration ask for a check is flagged with its reasons (issue 33)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.reconstruction_setup import DowelSettings
from workbench.services.reconstruction.refit_check import (
    EDIT_RADIUS_MM,
    MAX_AWAY_MM,
    compare_refit,
    edited_landmarks,
)
from workbench.services.reconstruction.service import FitInputs

#: a face of 2 000 points spread over a 160 x 200 x 60 mm box (input frame, mm)
FACE = np.random.default_rng(3).uniform([-80, -120, 0], [80, 80, 60], (2000, 3))
SKULL = Mesh(np.eye(3), np.array([[0, 1, 2]]))
LMS = LandmarkSet.from_points("skull", {"n": (0, 0, 60), "pr": (0, -70, 55), "go_l": (50, -90, 0)})


def _rot_z(deg: float) -> np.ndarray:
    a = np.radians(deg)
    m = np.eye(4)
    m[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return m


def fit(face=FACE, frame=None, landmarks=LMS, dowels=None, check="confident"):
    inputs = FitInputs(SKULL, landmarks, dowels=dowels or DowelSettings())
    registration = SimpleNamespace(figures={"self_check": {"outcome": check, "reasons": ["why"]}})
    recon = SimpleNamespace(
        input_to_head=np.eye(4) if frame is None else frame,
        face=SimpleNamespace(vertices=np.asarray(face, float)),
        registration=registration,
    )
    return SimpleNamespace(recon=recon, inputs=inputs)


def test_a_local_edit_with_a_local_change_is_safe():
    moved = LMS.with_landmark(replace(LMS["pr"], position=np.array([0.0, -72.0, 56.0])))
    face = FACE.copy()
    near = np.linalg.norm(FACE - [0, -71, 55], axis=1) < 20
    face[near] += [0.0, -2.0, 1.0]  # the face moves under the edited landmark only
    change = compare_refit(fit(), fit(face, landmarks=moved))
    assert change.safe and change.edited == ("pr",), change
    assert change.rotation_deg < 1e-6 and change.away_mm < 1e-9


def test_a_turned_face_is_not_safe():
    change = compare_refit(fit(), fit(frame=_rot_z(30.0)))
    assert not change.safe and abs(change.rotation_deg - 30.0) < 1e-6
    assert "turned 30 degrees" in change.text()


def test_a_face_moving_away_from_the_edit_is_not_safe():
    moved = LMS.with_landmark(replace(LMS["pr"], position=np.array([0.0, -72.0, 56.0])))
    face = FACE + [0.0, 0.0, 2.0 * MAX_AWAY_MM]  # everything moves, also far from pr
    change = compare_refit(fit(), fit(face, landmarks=moved))
    assert not change.safe and change.away_mm > MAX_AWAY_MM
    assert "away from the landmark(s) changed (pr)" in change.text()
    # the same move after a settings change (a new build) is expected: no such reason
    heavy = DowelSettings(build="heavy")
    assert compare_refit(fit(), fit(face, landmarks=moved, dowels=heavy)).safe


def test_a_self_check_that_starts_to_doubt_is_not_safe():
    change = compare_refit(fit(), fit(check="check"))
    assert not change.safe and "asks for a check: why" in change.text()
    assert compare_refit(fit(check="check"), fit(check="check")).safe  # already in doubt


def test_edited_landmarks_lists_moved_added_and_removed_codes():
    before = FitInputs(SKULL, LMS)
    after = FitInputs(
        SKULL,
        LMS.without("go_l").with_landmark(
            replace(LMS["n"], code="g", position=np.array([0.0, 20.0, 62.0]))
        ),
    )
    edited = edited_landmarks(before, after)
    assert sorted(edited) == ["g", "go_l"] and edited["g"].shape == (1, 3)
    assert EDIT_RADIUS_MM > 0
