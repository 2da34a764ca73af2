"""The registration's self-check: confident, check or refused, from its figures."""

from __future__ import annotations

import pytest

from workbench.core.errors import InputError
from workbench.services.registration.skull_check import (
    FACE_CHECK,
    FACE_REFUSE,
    WHAT_TO_GIVE,
    OrientationRefused,
    judge,
    refusal,
)

GOOD = {
    "face_observed": 0.87,
    "symmetry_deg": 1.2,
    "asymmetry_mm": 2.5,
    "scale": 1.05,
    "jaw_shift_mm": 2.0,
}
JAW = {"present": True, "bone_area": 1.4}


def test_a_registration_with_good_figures_is_confident():
    check = judge(GOOD, "search", JAW)
    assert check.outcome == "confident" and not check.reasons and check.headline is None


def test_a_face_skeleton_off_the_bone_is_refused_from_the_bone_alone_only():
    bad = {**GOOD, "face_observed": FACE_REFUSE - 0.05}
    searched = judge(bad, "search", JAW)
    assert searched.outcome == "refused" and searched.orientation_doubt
    assert "facial skeleton" in searched.reasons[0]
    # the user gave the orientation (or landmarks): never refused, but to be checked
    for method in ("hint", "seeds"):
        told = judge(bad, method, JAW)
        assert told.outcome == "check" and told.orientation_doubt
        assert told.headline.startswith("CHECK: only")


def test_doubtful_figures_ask_for_a_check_and_say_whether_the_orientation_is_doubted():
    face = judge({**GOOD, "face_observed": (FACE_REFUSE + FACE_CHECK) / 2}, "search", JAW)
    assert face.outcome == "check" and face.orientation_doubt
    sym = judge({**GOOD, "symmetry_deg": 12.0}, "search", JAW)
    assert sym.outcome == "check" and sym.orientation_doubt and "symmetry" in sym.reasons[0]
    # a child's skull or a pushed jaw: a check, but not of the orientation
    scale = judge({**GOOD, "scale": 0.7}, "search", JAW)
    assert scale.outcome == "check" and not scale.orientation_doubt
    jaw = judge({**GOOD, "jaw_shift_mm": 11.0}, "search", JAW)
    assert jaw.outcome == "check" and "fossae" in jaw.reasons[0]
    lost = judge({**GOOD, "jaw_shift_mm": None}, "search", {"present": False, "bone_area": 1.3})
    assert lost.outcome == "check" and "mandible" in lost.reasons[0]
    gone = judge({**GOOD, "jaw_shift_mm": None}, "search", {"present": False, "bone_area": 0.2})
    assert gone.outcome == "confident"


def test_missing_figures_are_not_held_against_a_registration():
    assert judge({}, "search", {}).outcome == "confident"
    assert judge({"face_observed": None, "scale": float("nan")}, "hint", {}).outcome == "confident"


def test_the_refusal_names_the_file_the_reasons_and_what_to_give():
    check = judge({**GOOD, "face_observed": 0.5}, "search", JAW)
    err = refusal(check, "bone.ply")
    assert isinstance(err, OrientationRefused) and isinstance(err, InputError)
    text = str(err)
    assert text.startswith("bone.ply: ") and "50 %" in text and WHAT_TO_GIVE in text


@pytest.mark.parametrize("value", [True, "x", None])
def test_odd_values_are_ignored(value):
    assert judge({"face_observed": value}, "search", {}).outcome == "confident"
