"""The one merge of a method's landmarks with a person's (reconstruct, the window, the CLI)."""

from __future__ import annotations

import numpy as np

from workbench.core.landmarks import Landmark, LandmarkSet, merge_user_landmarks


def _lm(code: str, x: float, status: str = "suggested", conf: float = 0.8) -> Landmark:
    return Landmark(code, np.array([x, 0.0, 0.0]), status, conf)


def test_placed_and_hand_absent_landmarks_survive_a_suggestion() -> None:
    found = LandmarkSet(
        "skull",
        (_lm("g", 1.0), _lm("n", 2.0), _lm("pg", 3.0), _lm("go_l", 4.0, "absent", 0.0)),
    )
    given = LandmarkSet(
        "skull",
        (
            _lm("g", 10.0, "placed", 1.0),  # a person placed it: kept where it is
            _lm("n", 20.0, "suggested", 0.4),  # an older suggestion: the new one wins
            Landmark("pg", np.full(3, np.nan), "absent", 1.0),  # absent by hand: stays absent
            _lm("zz_custom", 5.0, "placed", 1.0),  # a code the method does not give: kept
        ),
    )
    out = merge_user_landmarks(found, given).as_dict()
    assert out["g"][0] == 10.0 and out["n"][0] == 2.0 and "pg" not in out
    assert out["zz_custom"][0] == 5.0 and "go_l" not in out
    merged = merge_user_landmarks(found, given)
    assert [lm.code for lm in merged] == ["g", "n", "pg", "go_l", "zz_custom"]
    assert merged.surface == "skull"
    assert merge_user_landmarks(found, None) is found
