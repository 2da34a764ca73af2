"""Head frame from real landmark sets (FH from porions/orbitales, midline, mirroring)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from workbench.core.errors import LandmarkError
from workbench.core.landmarks import LandmarkSet
from workbench.services.landmarks.frame import head_frame_from_landmarks

# an adult skull's landmarks in the head frame (mm), roughly after Howells' means
CANONICAL = {
    "po_l": (62.0, 0.0, 0.0),
    "po_r": (-62.0, 0.0, 0.0),
    "or_l": (33.0, 0.0, 72.0),
    "or_r": (-33.0, 0.0, 72.0),
    "n": (0.0, 22.0, 88.0),
    "g": (0.0, 35.0, 92.0),
    "pr": (0.0, -42.0, 88.0),
    "me": (0.0, -85.0, 78.0),
    "op": (0.0, 40.0, -100.0),
    "b": (0.0, 110.0, 10.0),
}


def _moved(points: dict, matrix: np.ndarray) -> LandmarkSet:
    moved = {c: matrix[:3, :3] @ np.asarray(p) + matrix[:3, 3] for c, p in points.items()}
    return LandmarkSet.from_points("skull", moved)


@pytest.mark.parametrize("seed", range(5))
def test_frame_recovers_the_canonical_coordinates(seed: int) -> None:
    m = np.eye(4)
    m[:3, :3] = Rotation.random(random_state=seed).as_matrix()
    m[:3, 3] = np.random.default_rng(seed).normal(size=3) * 200
    frame = head_frame_from_landmarks(_moved(CANONICAL, m))
    assert not frame.mirrored_input
    for code, p in CANONICAL.items():
        got = frame.to_head(m[:3, :3] @ np.asarray(p) + m[:3, 3])
        assert np.allclose(got, p, atol=1e-9), code
    # and back into the user's frame
    p = np.asarray(CANONICAL["me"])
    assert np.allclose(
        frame.to_input(frame.to_head(m[:3, :3] @ p + m[:3, 3])), m[:3, :3] @ p + m[:3, 3]
    )


def test_mirrored_input_is_flagged() -> None:
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    assert head_frame_from_landmarks(_moved(CANONICAL, mirror)).mirrored_input


def test_missing_fh_landmarks_are_named() -> None:
    partial = {k: v for k, v in CANONICAL.items() if k not in ("po_r", "or_l", "or_r")}
    with pytest.raises(LandmarkError, match=r"po_r.*or_l or or_r"):
        head_frame_from_landmarks(LandmarkSet.from_points("skull", partial))
