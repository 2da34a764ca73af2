"""The skin warp of the age change: Kähler's landmark spline without a crease at its landmarks.

Units mm, any one frame (the age change's Frankfort frame).

Kähler's warp (§8.3.1, :func:`workbench.core.tps.fit_warp`) is
f(p) = Σ c_i ‖p − p_i‖ + A p + t.  Its kernel φ(r) = r has a kink at r = 0:
near a landmark the displacement grows like c_i ‖p − p_i‖, a cone.  The
age change's landmarks lie *on* the skin, and each one whose target does not
fit its neighbours' (a frontotemporale point held by its head norm while the
face around it changes) leaves a small conical dent or bump in the skin, a
crease that catches the light.

This warp uses the rounded kernel φ(r) = √(r² + c²) (Hardy's multiquadric;
c = :data:`CORE_MM` is the rounding radius): the same spline as Kähler's
farther than a few c from a landmark (φ − r < c²/2r), smooth everywhere, so
the skin bends over a few millimetres instead of creasing at a point.  Like
φ(r) = r it is conditionally negative definite of order 1 (Micchelli 1986),
so the system with the affine side conditions is solvable for distinct
landmarks, meets each landmark with λ_i = 0 exactly and reproduces any
affine map.  The regulariser λ_i ≥ 0 (mm) is subtracted from the diagonal,
as in :mod:`workbench.core.tps`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lu_factor, lu_solve
from scipy.spatial.distance import cdist

#: rounding radius c of the kernel √(r² + c²), mm.  Measured on the reference heads (largest
#: change of the angle between neighbouring forehead triangles, 25 → 3, 8, 12, 18, 40 y and
#: 18 → 3, 8, 40 y): at most 1.8° with φ = r, 1.1° with c = 5 mm.  Larger c smooths more
#: but ties the closely spaced mouth landmarks together: ageing 18 → 3 → 18 returned the
#: skin 1.09 mm (median) from where it started with φ = r, 1.22 mm with c = 5, 1.65 mm
#: with c = 10
CORE_MM = 5.0
#: points evaluated per block (block × landmarks kernel values at a time)
_BLOCK = 16_384


@dataclass(frozen=True, eq=False)
class RoundedWarp:
    """f(p) = Σ w_i √(‖p − p_i‖² + c²) + A p + t; callable on (k, 3) points in mm."""

    centres: np.ndarray  # (n, 3) landmarks, relative to ``offset``
    weights: np.ndarray  # (n, 3)
    affine: np.ndarray  # (4, 3): rows of A, then t
    offset: np.ndarray  # (3,)
    core_mm: float

    def __call__(self, points: np.ndarray) -> np.ndarray:
        x = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.offset
        out = np.empty_like(x)
        c2 = self.core_mm * self.core_mm
        for start in range(0, len(x), _BLOCK):
            part = x[start : start + _BLOCK]
            k = np.sqrt(cdist(part, self.centres, "sqeuclidean") + c2)
            out[start : start + _BLOCK] = k @ self.weights + part @ self.affine[:3] + self.affine[3]
        return out + self.offset


def fit_rounded_warp(
    source: np.ndarray,
    target: np.ndarray,
    smoothing: float | np.ndarray = 0.0,
    core_mm: float = CORE_MM,
) -> RoundedWarp:
    """The rounded-kernel warp taking ``source`` landmarks (n, 3; mm, distinct) to ``target``.

    ``smoothing`` λ ≥ 0 (mm), one for all or one per landmark: 0 meets the
    landmark exactly, larger values approach it loosely.  Needs n ≥ 4 landmarks
    not all in one plane (the affine part); raises ValueError otherwise.
    """
    src = np.asarray(source, dtype=np.float64)
    dst = np.asarray(target, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3:
        raise ValueError(f"source {src.shape} and target {dst.shape} must both be (n, 3)")
    n = len(src)
    lam = np.broadcast_to(np.asarray(smoothing, dtype=np.float64), (n,))
    if not np.all(np.isfinite(lam)) or (lam < 0).any():
        raise ValueError("smoothing must be finite and >= 0")
    offset = src.mean(axis=0)
    p = src - offset
    if n < 4 or np.linalg.matrix_rank(p, tol=1e-9 * max(1.0, float(np.abs(p).max()))) < 3:
        raise ValueError("the rounded warp needs at least four landmarks not in one plane")
    a = np.zeros((n + 4, n + 4))
    a[:n, :n] = np.sqrt(cdist(p, p, "sqeuclidean") + core_mm * core_mm)
    a[np.arange(n), np.arange(n)] -= lam
    a[:n, n : n + 3] = p
    a[:n, n + 3] = 1.0
    a[n:, :n] = a[:n, n:].T
    b = np.zeros((n + 4, 3))
    b[:n] = dst - offset
    x = lu_solve(lu_factor(a, check_finite=False), b, check_finite=False)
    return RoundedWarp(p, x[:n], x[n:], offset, float(core_mm))
