"""Per-landmark regularisation of the thin-plate spline (core.tps.fit_warp)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.tps import fit_warp


def test_landmarks_with_zero_smoothing_are_met_exactly_the_others_approached() -> None:
    rng = np.random.default_rng(3)
    src = rng.normal(scale=50.0, size=(30, 3))
    dst = src + rng.normal(scale=3.0, size=(30, 3))
    lam = np.where(np.arange(30) < 10, 0.0, 50.0)
    w = fit_warp(src, dst, smoothing=lam)
    res = np.linalg.norm(w(src) - dst, axis=1)
    assert res[:10].max() < 1e-6
    assert res[10:].mean() > 0.1  # the loose ones are only approached
    exact = fit_warp(src, dst)
    assert np.linalg.norm(exact(src) - dst, axis=1).max() < 1e-6


def test_bad_per_point_smoothing_is_refused() -> None:
    src = np.eye(3).tolist() + [[1.0, 1.0, 1.0], [2.0, 0.5, 0.1]]
    with pytest.raises(ValueError):
        fit_warp(np.array(src), np.array(src), smoothing=np.ones(3))
    with pytest.raises(ValueError):
        fit_warp(np.array(src), np.array(src), smoothing=-np.ones(5))
