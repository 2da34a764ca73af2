"""The final warp's anchors: chosen on the reference, their hold fading continuously."""

from __future__ import annotations

import numpy as np

from workbench.services.reconstruction.reconstruct import (
    ANCHOR_CLEARANCE_MM,
    ANCHOR_SPACING_MM,
    ANCHOR_TAPER_MM,
    MOVING_MM,
    _anchors,
)

PTS = np.column_stack([np.arange(400) * 0.25, np.zeros(400), np.zeros(400)])
#: the anchor of the cell starting at one spacing along the line
PROBE = int(round(ANCHOR_SPACING_MM / 0.25))


def _hold(distance: float, move: float) -> float:
    """Hold of the probe anchor with a point ``distance`` mm before it moved by ``move`` mm."""
    p = PTS[PROBE] - np.array([distance, 0.0, 0.0]) + np.array([0.0, 0.1, 0.0])
    anchors, hold = _anchors(PTS, PTS, [p], [p + np.array([0.0, 0.0, move])])
    return dict(zip(anchors.tolist(), hold.tolist(), strict=True)).get(PROBE, 0.0)


def test_anchors_are_cells_of_the_reference_not_of_the_moving_skin():
    a1, _ = _anchors(PTS, PTS, [], [])
    a2, _ = _anchors(PTS, PTS + 1e-7, [], [])
    assert PROBE in a1.tolist()
    np.testing.assert_array_equal(a1, a2)


def test_an_anchor_fades_in_beyond_the_clearance_without_a_step():
    d = np.arange(0.5, ANCHOR_CLEARANCE_MM + ANCHOR_TAPER_MM + 3.0, 0.05)
    h = np.array([_hold(x, 2.0) for x in d])
    assert np.all(h[d < ANCHOR_CLEARANCE_MM - 0.01] == 0.0)  # none inside the clearance
    assert np.allclose(h[d > ANCHOR_CLEARANCE_MM + ANCHOR_TAPER_MM + 0.01], 1.0)
    assert np.all(np.diff(h) >= -1e-12)
    assert np.abs(np.diff(h)).max() < 0.05  # a ramp, no jump anywhere


def test_a_point_barely_moving_barely_releases_its_anchors():
    x = ANCHOR_CLEARANCE_MM - 4.0  # well inside the clearance of a point that moves
    assert _hold(x, 10 * MOVING_MM) == 0.0
    assert _hold(x, 0.0) == 1.0
    assert abs(_hold(x, 0.049) - _hold(x, 0.051)) < 0.05  # no threshold on the move
