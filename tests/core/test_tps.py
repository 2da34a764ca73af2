"""Landmark warp φ(r) = r plus affine (workbench.core.tps)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import RBFInterpolator

from workbench.core.tps import LandmarkWarp, fit_warp, similarity_transform


def spread_points(n: int, rng: np.random.Generator, size: float = 100.0) -> np.ndarray:
    """``n`` points in a cube of ``size`` mm, no two closer than a fraction of the spacing."""
    spacing = size / max(n, 2) ** (1 / 3)
    pts = np.empty((0, 3))
    while len(pts) < n:
        cand = rng.uniform(-size / 2, size / 2, (4 * n, 3))
        for c in cand:
            if len(pts) == 0 or np.min(np.linalg.norm(pts - c, axis=1)) > 0.3 * spacing:
                pts = np.vstack([pts, c])
                if len(pts) == n:
                    break
    return pts


def smooth_displacement(p: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    k = rng.normal(size=(3, 3)) / 60.0
    return 5.0 * np.sin(p @ k) + rng.normal(0, 1.0, p.shape)


def reference_warp(
    src: np.ndarray, dst: np.ndarray, x: np.ndarray, smoothing: float = 0.0
) -> np.ndarray:
    """The block system solved densely with numpy.linalg.solve, evaluated directly."""
    n = len(src)
    # φ = r is conditionally negative definite: smoothing subtracts λ I
    k = np.linalg.norm(src[:, None] - src[None], axis=2) - smoothing * np.eye(n)
    p = np.hstack([src, np.ones((n, 1))])
    a = np.block([[k, p], [p.T, np.zeros((4, 4))]])
    sol = np.linalg.solve(a, np.vstack([dst, np.zeros((4, 3))]))
    r = np.linalg.norm(x[:, None] - src[None], axis=2)
    return r @ sol[:n] + np.hstack([x, np.ones((len(x), 1))]) @ sol[n:]


def bending(warp: LandmarkWarp) -> float:
    """-trace(Wᵀ K W): the (non-negative) bending energy of the RBF part."""
    c = warp.centres
    k = np.linalg.norm(c[:, None] - c[None], axis=2)
    return float(-np.trace(warp.weights.T @ k @ warp.weights))


landmark_sets = st.tuples(st.integers(4, 200), st.integers(0, 2**32 - 1))


@settings(max_examples=30, deadline=None)
@given(case=landmark_sets)
def test_landmarks_are_interpolated_exactly(case):
    n, seed = case
    rng = np.random.default_rng(seed)
    src = spread_points(n, rng) + rng.uniform(-300, 300, 3)
    dst = src + smooth_displacement(src, rng)
    warp = fit_warp(src, dst)
    assert warp.method == "tps"
    scale = np.abs(dst).max()
    assert np.abs(warp(src) - dst).max() <= 1e-9 * scale
    assert warp.residuals(src, dst).max() <= 1e-9 * scale


@settings(max_examples=30, deadline=None)
@given(
    case=landmark_sets,
    a=st.lists(st.floats(-1, 1), min_size=9, max_size=9),
    t=st.lists(st.floats(-100, 100), min_size=3, max_size=3),
)
def test_affine_maps_are_reproduced_everywhere(case, a, t):
    n, seed = case
    rng = np.random.default_rng(seed)
    m = np.eye(3) + 0.5 * np.array(a).reshape(3, 3)
    if abs(np.linalg.det(m)) < 0.1:
        m = np.eye(3)
    src = spread_points(n, rng)
    warp = fit_warp(src, src @ m.T + t)
    x = rng.uniform(-150, 150, (500, 3))
    np.testing.assert_allclose(warp(x), x @ m.T + t, rtol=0, atol=1e-9 * 300)
    assert np.abs(warp.weights).max() < 1e-10


@settings(max_examples=20, deadline=None)
@given(case=landmark_sets)
def test_identity_when_source_equals_target(case):
    n, seed = case
    rng = np.random.default_rng(seed)
    src = spread_points(n, rng)
    warp = fit_warp(src, src)
    x = rng.uniform(-100, 100, (300, 3))
    # Rounding error in the affine part grows with the conditioning of the
    # landmark spread: four nearly coplanar points (smallest singular value of
    # the centred set a few µm) legitimately lose ~1e-7 mm over a 100 mm box.
    sv = np.linalg.svd(src - src.mean(axis=0), compute_uv=False)
    tol = 1e-12 * 100.0 * max(sv[0] / sv[-1], 1.0)
    np.testing.assert_allclose(warp(x), x, rtol=0, atol=max(tol, 1e-10))
    assert np.abs(warp.weights).max() < 1e-12


def fallback_sets(rng: np.random.Generator) -> dict[str, np.ndarray]:
    plane = np.c_[rng.uniform(-50, 50, (12, 2)), np.zeros(12)]
    tilt = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    line = np.outer(rng.uniform(-50, 50, 6), [1.0, 2.0, -0.5])
    return {
        "one": rng.normal(size=(1, 3)) * 20,
        "two": rng.normal(size=(2, 3)) * 20,
        "three": rng.normal(size=(3, 3)) * 20,
        "coplanar": plane @ tilt.T + 7.0,
        "collinear": line + 3.0,
    }


@pytest.mark.parametrize("case", ["one", "two", "three", "coplanar", "collinear"])
def test_fallback_cases_still_interpolate(case):
    rng = np.random.default_rng(11)
    src = fallback_sets(rng)[case]
    dst = src + rng.normal(0, 4.0, src.shape)
    warp = fit_warp(src, dst)
    assert warp.method == "similarity+rbf"
    assert np.abs(warp(src) - dst).max() < 1e-9 * np.abs(dst).max()
    assert np.isfinite(warp(rng.uniform(-100, 100, (50, 3)))).all()


def test_no_landmarks_is_the_identity_and_one_is_a_translation():
    x = np.random.default_rng(0).normal(size=(10, 3))
    np.testing.assert_array_equal(fit_warp(np.zeros((0, 3)), np.zeros((0, 3)))(x), x)
    warp = fit_warp([[1.0, 2.0, 3.0]], [[2.0, 2.0, 5.0]])
    np.testing.assert_allclose(warp(x), x + [1.0, 0.0, 2.0], atol=1e-14)


def test_two_landmarks_give_an_exact_similarity():
    src = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    dst = np.array([[5.0, 5.0, 5.0], [5.0, 25.0, 5.0]])
    m = similarity_transform(src, dst)
    np.testing.assert_allclose(src @ m[:3, :3].T + m[:3, 3], dst, atol=1e-12)
    assert np.linalg.det(m[:3, :3]) == pytest.approx(8.0)  # scale 2, no reflection


def test_coincident_source_landmarks_are_refused():
    src = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 0]])
    with pytest.raises(ValueError, match="coincide"):
        fit_warp(src, src + 1.0)
    with pytest.raises(ValueError):
        fit_warp(src[:4], src[:3])
    with pytest.raises(ValueError):
        fit_warp(src[:4], src[:4], smoothing=-1.0)
    with pytest.raises(ValueError):
        fit_warp([[np.nan, 0, 0]], [[0, 0, 0]])


def test_smoothing_trades_residuals_for_less_bending():
    rng = np.random.default_rng(3)
    src = spread_points(40, rng)
    dst = src + smooth_displacement(src, rng)
    warps = [fit_warp(src, dst, smoothing=s) for s in (0.0, 2.0, 20.0)]
    residuals = [w.residuals(src, dst).max() for w in warps]
    energy = [bending(w) for w in warps]
    assert residuals[0] < 1e-9 and residuals[1] > 1e-3
    assert residuals[1] < residuals[2]
    assert energy[0] > energy[1] > energy[2] > 0
    # the smoothed warp is the one of the regularised block system, and scipy's
    x = rng.uniform(-60, 60, (200, 3))
    np.testing.assert_allclose(warps[1](x), reference_warp(src, dst, x, 2.0), atol=1e-8)
    theirs = RBFInterpolator(src, dst, kernel="linear", degree=1, smoothing=2.0)(x)
    np.testing.assert_allclose(warps[1](x), theirs, atol=1e-8)


@pytest.mark.parametrize("chunk", [1, 1000, 50_000, 1 << 22])
@pytest.mark.parametrize("workers", [1, 2, 3])
def test_chunked_threaded_apply_equals_dense_reference(chunk, workers):
    rng = np.random.default_rng(4)
    src = spread_points(60, rng)
    dst = src + smooth_displacement(src, rng)
    x = np.vstack([rng.uniform(-80, 80, (3000, 3)), src, src + 1e-7])  # incl. landmarks
    got = fit_warp(src, dst)(x, chunk_elements=chunk, workers=workers)
    np.testing.assert_allclose(got, reference_warp(src, dst, x), rtol=0, atol=1e-9)


def test_thread_count_does_not_change_a_single_bit():
    """The chunks are fixed, the threads only share them out: a head built on any number
    of cores gets the same content hash."""
    rng = np.random.default_rng(5)
    src = spread_points(80, rng)
    warp = fit_warp(src, src + smooth_displacement(src, rng))
    x = rng.uniform(-80, 80, (40_000, 3))
    one = warp(x, chunk_elements=20_000, workers=1)
    for workers in (2, 3, 7):
        assert np.array_equal(warp(x, chunk_elements=20_000, workers=workers), one)


@settings(max_examples=15, deadline=None)
@given(case=st.tuples(st.integers(4, 120), st.integers(0, 2**32 - 1)))
def test_same_function_as_scipy_linear_rbf(case):
    """scipy's 'linear' kernel is -r: the same interpolant (weights change sign)."""
    n, seed = case
    rng = np.random.default_rng(seed)
    src = spread_points(n, rng)
    dst = src + smooth_displacement(src, rng)
    x = rng.uniform(-70, 70, (400, 3))
    ours = fit_warp(src, dst)(x)
    theirs = RBFInterpolator(src, dst, kernel="linear", degree=1)(x)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-8)


def test_a_million_points_in_bounded_memory():
    rng = np.random.default_rng(5)
    src = spread_points(500, rng, size=160.0)
    warp = fit_warp(src, src + smooth_displacement(src, rng))
    x = rng.uniform(-90, 90, (1_000_000, 3))
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base, _ = tracemalloc.get_traced_memory()
        y = warp(x)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    extra = peak - base - y.nbytes
    assert extra < 200 * 2**20, f"{extra / 2**20:.0f} MB beyond input and output"
    sample = rng.choice(len(x), 500, replace=False)
    np.testing.assert_allclose(
        y[sample],
        reference_warp(warp.centres + warp.offset, warp(warp.centres + warp.offset), x[sample]),
        atol=1e-7,
    )


def test_weighted_similarity_ignores_a_zero_weight_outlier():
    rng = np.random.default_rng(3)
    src = rng.normal(0.0, 30.0, (40, 3))
    true = similarity_transform(src, src)  # identity to start from
    true[:3, :3] = 1.2 * np.linalg.qr(rng.normal(size=(3, 3)))[0]
    if np.linalg.det(true[:3, :3]) < 0:
        true[:3, :3] *= -1.0
    true[:3, 3] = (5.0, -7.0, 11.0)
    dst = src @ true[:3, :3].T + true[:3, 3]
    dst[0] += 80.0  # one wild pair
    w = np.ones(40)
    np.testing.assert_allclose(
        similarity_transform(src, dst, w), similarity_transform(src, dst), atol=1e-9
    )
    w[0] = 0.0
    np.testing.assert_allclose(similarity_transform(src, dst, w), true, atol=1e-9)
    with pytest.raises(ValueError, match="weights"):
        similarity_transform(src, dst, np.zeros(40))
