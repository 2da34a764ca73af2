"""Landmark-driven space warp: radial basis functions with φ(r) = r plus an affine part.

This is the deformation of Kähler's dissertation §8.3.1 (Eq. 8.1)::

    f(p) = Σ_i c_i ‖p − p_i‖ + R p + t

with side conditions Σ c_i = 0 and Σ c_i p_iᵀ = 0, solved as one
``(N+4) x (N+4)`` block system ``[[P, Q], [Qᵀ, 0]] X = [q; 0]`` by LU
decomposition with partial pivoting, all three output coordinates at once.
φ(r) = r is the biharmonic kernel in 3-D, so the warp is the 3-D thin-plate
spline: it interpolates the landmarks exactly and reproduces any affine map
exactly (the RBF weights then vanish).

Units and frames
----------------
Source and target landmarks, and the points the warp is applied to, are in
millimetres in one common frame; the warp does not change units.

Degenerate landmark sets
------------------------
⚠ The block system is singular when fewer than four landmarks are given or
when they are coplanar (the affine part is then undetermined).  The
dissertation (§8.4.2) nevertheless speaks of a warp "from three or more
landmarks".  Our documented fallback: fit a least-squares *similarity*
transform (rotation, uniform scale, translation; Umeyama 1991, reflections
excluded) and add a pure RBF term ``Σ c_i ‖p − p_i‖`` without side
conditions that takes up the residuals.  The distance matrix of distinct
points is non-singular (Micchelli 1986), so the fallback still interpolates
every landmark exactly: 0 landmarks → identity, 1 → translation,
2 → similarity (exact), 3+ coplanar → similarity + RBF.

Regularisation
--------------
``smoothing`` λ ≥ 0 (mm) regularises the fit: the warp then approximates
instead of interpolates, trading landmark residuals for a smoother field
(useful with noisy landmarks).  φ(r) = r is conditionally *negative*
definite (its bending energy is ``−cᵀ P c``), so the regularised system
subtracts λ·I from the kernel block, ``[[P − λI, Q], [Qᵀ, 0]]``; this is
the minimiser of ``Σ‖f(p_i) − q_i‖² + λ·(−cᵀ P c)`` and the same warp as
scipy's ``RBFInterpolator(kernel="linear", degree=1, smoothing=λ)`` (whose
kernel is −r).  Adding λ·I instead would make the field *less* smooth.
λ = 0 is exact interpolation.

Evaluation is chunked: at most ``chunk_elements`` kernel values exist at a
time, so 10⁶ points × 500 landmarks never builds a 4 GB matrix.  Chunks run
in a small thread pool (numpy releases the GIL in the heavy kernels).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lu_factor, lu_solve
from scipy.spatial.distance import cdist

from workbench.core.threads import worker_count

_DEFAULT_CHUNK = 131_072  # kernel values per chunk: 1 MB of float64 stays in L2 cache


def _as_points(x: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} contains NaN or infinite coordinates")
    return a


def similarity_transform(
    source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None
) -> np.ndarray:
    """Least-squares similarity (no reflection) mapping ``source`` onto ``target``.

    Parameters
    ----------
    source, target : (n, 3) float64
        Corresponding points in mm.
    weights : (n,) float64, optional
        Non-negative weight of each pair (weighted Umeyama); equal when omitted.

    Returns
    -------
    (4, 4) float64
        Homogeneous matrix ``M`` with ``target ≈ s R source + t``.
    """
    src = _as_points(source, "source")
    dst = _as_points(target, "target")
    n = len(src)
    m = np.eye(4)
    if n == 0:
        return m
    if weights is None:
        mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (n,) or not (w >= 0).all() or not w.sum() > 0:
            raise ValueError("weights must be n non-negative numbers, not all zero")
        w = w / w.sum()
        mu_s, mu_d = w @ src, w @ dst
    if n == 1:
        m[:3, 3] = mu_d - mu_s
        return m
    a, b = src - mu_s, dst - mu_d
    if weights is None:
        var_s = (a**2).sum() / n
        cov = b.T @ a / n
    else:
        var_s = float(w @ (a**2).sum(axis=1))
        cov = (b * w[:, None]).T @ a
    if var_s == 0.0:
        m[:3, 3] = mu_d - mu_s
        return m
    u, sig, vt = np.linalg.svd(cov)
    d = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        d[-1] = -1.0
    rot = u @ np.diag(d) @ vt
    # Umeyama's scale; exact for two points too (the covariance is rank 1
    # and the rotation then is the minimal one about the free axis).
    scale = float((sig * d).sum() / var_s)
    m[:3, :3] = scale * rot
    m[:3, 3] = mu_d - scale * rot @ mu_s
    return m


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Run the block with the BLAS limited to one thread.

    Each warp parallelises over point chunks with its own threads; letting
    OpenBLAS start threads of its own inside every small matrix product makes
    the two fight over the cores (measured: 2.5 s instead of 0.19 s for 500
    landmarks onto 2.5e5 points on 2 cores).  threadpoolctl changes a
    process-wide setting, so BLAS calls in other threads are single-threaded
    while a warp runs (slower, never wrong).
    """
    global _BLAS_CONTROLLER
    if _BLAS_CONTROLLER is None:
        # scanning the loaded libraries costs ~6 ms; do it once (the BLAS is
        # loaded with numpy, before any warp runs)
        from threadpoolctl import ThreadpoolController

        _BLAS_CONTROLLER = ThreadpoolController()
    with _BLAS_CONTROLLER.limit(limits=1, user_api="blas"):
        yield


_BLAS_CONTROLLER = None


def _kernel_block(
    x: np.ndarray, centres: np.ndarray, gram: np.ndarray, centre_norm2: float
) -> np.ndarray:
    """``(k, N)`` distances ‖x_j − p_i‖ for one chunk of points ``x`` ``(k, 3)``.

    Squared distances come from one small GEMM,
    ``[x, 1, ‖x‖²] @ [[-2 pᵀ], [‖p‖²], [1]]``: cache-friendly and fast, but
    it loses digits when a point nearly coincides with a centre (the error
    is about ``4e-16 (‖x‖² + ‖p‖²)``).  Rows whose smallest value is below
    ``1e-9`` of that scale are recomputed directly, so every distance is
    accurate to about 1e-9 mm (relative to the landmark spread) and
    landmarks are interpolated to machine precision.
    """
    k = len(x)
    xa = np.empty((k, 5))
    xa[:, :3] = x
    xa[:, 3] = 1.0
    norm2 = np.einsum("ij,ij->i", x, x)
    xa[:, 4] = norm2
    d2 = xa @ gram
    suspect = np.flatnonzero(d2.min(axis=1) < 1e-9 * (norm2 + centre_norm2 + 1e-300))
    if len(suspect):
        diff = x[suspect, None, :] - centres[None, :, :]
        d2[suspect] = np.einsum("ijk,ijk->ij", diff, diff)
    return np.sqrt(d2, out=d2)


@dataclass(frozen=True)
class LandmarkWarp:
    """A fitted warp ℝ³ → ℝ³ (mm → mm).  Build it with :func:`fit_warp`.

    Attributes
    ----------
    centres : (N, 3)
        Source landmarks p_i (shifted by ``offset``).
    weights : (N, 3)
        RBF weights c_i.
    affine : (4, 3)
        Rows of ``Rᵀ`` stacked over ``tᵀ`` (in the shifted frame).
    offset : (3,)
        Centroid of the source landmarks; evaluation works relative to it
        for numerical accuracy.
    method : str
        ``"tps"`` or the fallback ``"similarity+rbf"``.
    smoothing : float
        Regulariser λ used in the fit.
    """

    centres: np.ndarray
    weights: np.ndarray
    affine: np.ndarray
    offset: np.ndarray
    method: str
    smoothing: float = 0.0

    @property
    def n_landmarks(self) -> int:
        return int(len(self.centres))

    def __call__(
        self,
        points: np.ndarray,
        *,
        chunk_elements: int = _DEFAULT_CHUNK,
        workers: int | None = None,
    ) -> np.ndarray:
        return self.apply(points, chunk_elements=chunk_elements, workers=workers)

    def apply(
        self,
        points: np.ndarray,
        *,
        chunk_elements: int = _DEFAULT_CHUNK,
        workers: int | None = None,
    ) -> np.ndarray:
        """Warp ``points`` ``(n, 3)`` mm; returns a new ``(n, 3)`` array.

        Memory beyond input and output is ``O(chunk_elements)`` per worker.
        """
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
        out = np.empty_like(pts)
        n_c = max(self.n_landmarks, 1)
        step = max(64, int(chunk_elements) // n_c)
        c2 = np.einsum("ij,ij->i", self.centres, self.centres)
        gram = np.vstack([-2.0 * self.centres.T, c2[None], np.ones((1, len(c2)))])
        c2max = float(c2.max(initial=0.0))

        def run(starts: np.ndarray) -> None:
            for start in starts.tolist():
                stop = min(start + step, len(pts))
                x = pts[start:stop] - self.offset
                y = x @ self.affine[:3] + self.affine[3]
                if self.n_landmarks:
                    y += _kernel_block(x, self.centres, gram, c2max) @ self.weights
                out[start:stop] = y + self.offset

        if workers is None:
            workers = worker_count()
        workers = max(1, min(int(workers), len(pts) // (4 * step) or 1))
        # the chunks are the same whatever the number of threads (each thread takes a run
        # of them), so the result is too, to the last bit: a head built on a 2-core and a
        # 16-core machine has one content hash
        blocks = np.array_split(np.arange(0, len(pts), step), workers)
        # our threads split the work; BLAS threads inside each small GEMM
        # would only contend with them (up to 10x slower with OpenBLAS)
        with single_threaded_blas():
            if workers == 1:
                run(blocks[0])
            else:
                with ThreadPoolExecutor(max_workers=workers) as pool:
                    list(pool.map(run, blocks))
        return out

    def residuals(self, source: np.ndarray, target: np.ndarray) -> np.ndarray:
        """``(N,)`` distances ‖f(p_i) − q_i‖ in mm."""
        return np.linalg.norm(self.apply(source) - np.asarray(target, float), axis=1)


def _affine_rank(points: np.ndarray) -> int:
    """Dimension of the affine hull of ``points`` (0 to 3), scale-aware."""
    if len(points) < 2:
        return 0
    centred = points - points.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    if s[0] == 0.0:
        return 0
    return int((s > s[0] * 1e-9).sum())


def fit_warp(
    source: np.ndarray, target: np.ndarray, *, smoothing: float | np.ndarray = 0.0
) -> LandmarkWarp:
    """Fit the warp mapping ``source`` landmarks onto ``target`` landmarks.

    Parameters
    ----------
    source, target : (N, 3) float64
        Corresponding landmarks p_i → q_i in mm.  Source points must be
        distinct.
    smoothing : float or (N,) array
        Regulariser λ ≥ 0 (0 = exact interpolation), one for all landmarks
        or one per landmark: a landmark with λ_i = 0 is still met exactly
        while the others are only approached (its residual is λ_i times its
        kernel weight), e.g. targets met exactly and guesses followed loosely.

    Returns
    -------
    LandmarkWarp
    """
    src = _as_points(source, "source landmarks")
    dst = _as_points(target, "target landmarks")
    if src.shape != dst.shape:
        raise ValueError(f"source {src.shape} and target {dst.shape} landmarks differ in number")
    n = len(src)
    lam = np.asarray(smoothing, dtype=np.float64)
    if lam.ndim not in (0, 1) or (lam.ndim == 1 and lam.shape != (n,)):
        raise ValueError(f"smoothing must be a number or one per landmark ({n})")
    if not np.all(np.isfinite(lam)) or (lam < 0).any():
        raise ValueError("smoothing must be >= 0")
    if n > 1:
        uniq = np.unique(src, axis=0)
        if len(uniq) != n:
            raise ValueError(
                f"{n - len(uniq)} source landmarks coincide; a warp needs distinct points"
            )
    offset = src.mean(axis=0) if n else np.zeros(3)
    p = src - offset
    q = dst - offset
    if n >= 4 and _affine_rank(p) == 3:
        return _fit_tps(p, q, offset, lam if lam.ndim else float(lam))
    return _fit_similarity_rbf(p, q, offset, float(lam.max()) if lam.size else 0.0)


def _kernel_matrix(p: np.ndarray, smoothing: float | np.ndarray) -> np.ndarray:
    k = cdist(p, p)  # exact pairwise distances, 20x faster than broadcasting
    if np.any(smoothing):
        k[np.diag_indices_from(k)] -= smoothing  # see "Regularisation" above
    return k


def _fit_tps(
    p: np.ndarray, q: np.ndarray, offset: np.ndarray, smoothing: float | np.ndarray
) -> LandmarkWarp:
    n = len(p)
    a = np.zeros((n + 4, n + 4))
    a[:n, :n] = _kernel_matrix(p, smoothing)
    a[:n, n : n + 3] = p
    a[:n, n + 3] = 1.0
    a[n:, :n] = a[:n, n:].T
    b = np.zeros((n + 4, 3))
    b[:n] = q
    with single_threaded_blas():  # BLAS threads only slow an (N+4)² LU down
        x = lu_solve(lu_factor(a, check_finite=False), b, check_finite=False)
    return LandmarkWarp(
        centres=_ro(p),
        weights=_ro(x[:n]),
        affine=_ro(x[n:]),
        offset=_ro(offset),
        method="tps",
        smoothing=float(np.max(smoothing)),
    )


def _fit_similarity_rbf(
    p: np.ndarray, q: np.ndarray, offset: np.ndarray, smoothing: float
) -> LandmarkWarp:
    m = similarity_transform(p, q)
    affine = np.vstack([m[:3, :3].T, m[:3, 3]])
    n = len(p)
    weights = np.zeros((n, 3))
    if n >= 2:
        residual = q - (p @ affine[:3] + affine[3])
        if np.abs(residual).max() > 1e-12 * max(1.0, np.abs(q).max()):
            with single_threaded_blas():
                weights = np.linalg.solve(_kernel_matrix(p, smoothing), residual)
    return LandmarkWarp(
        centres=_ro(p),
        weights=_ro(weights),
        affine=_ro(affine),
        offset=_ro(offset),
        method="similarity+rbf",
        smoothing=float(smoothing),
    )


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float64)
    a.setflags(write=False)
    return a
