"""New landmark positions from target distances: the hard/soft constraint solve of Kähler §8.5.3.

Units mm; the landmarks are in the Frankfort frame (x to the subject's left,
y up, z toward the face), because axis-aligned measurements (horizontal,
vertical, depth) are taken along those axes.

The unknowns are the new landmark coordinates, solved for each axis on its
own.  Every constraint is a coordinate *difference* q_j − q_k:

* **hard** constraints carry the target distances: an axis-aligned one gives
  one row on its axis; a Euclidean one is linearised (Kähler: the current
  direction u of j − k is kept and scaled to the target length L, giving
  the three rows q_j − q_k = L·u on x, y, z), solved, the direction
  re-measured and solved again.  Kähler stops after three rounds; we iterate
  until the landmarks move less than :data:`TOLERANCE_MM` or for
  :data:`MAX_ROUNDS` rounds: the fixed point is approached linearly, and on
  the reference heads aged 18 → 3 y three rounds leave 0.6 mm of a target
  unmet, ten 0.12 mm, a hundred 0.012 mm (each round is three small
  matrix-vector products).
* **soft** constraints are landmark pairs (nearby ones, and measurements
  without norms) whose difference on an axis should scale with the global
  factor s: Kähler's Eq. 8.2 gives each one an unknown factor λ_i with the
  rows q_j − q_k − λ_i·d̃_i = 0 and λ_i = s, d̃_i being the *current*
  difference.  λ_i appears in those two rows only, so it is eliminated in
  closed form: the least-squares minimum over λ_i of
  (r − λ d̃)² + (λ − s)² is (r − s·d̃)² / (1 + d̃²).  Each soft pair thus
  becomes one row q_j − q_k = s·d̃ with weight 1/√(1 + d̃²): the same
  minimiser as the full system with half the unknowns (and λ_i is
  recovered as (s + d̃·r)/(1 + d̃²) for the report).  The weight shows
  Kähler's "residual balance": a soft pair 50 mm long weighs 1/50 of a hard
  row, so targets are met closely while the rest follows s; a soft pair with
  no extent on an axis (two midline landmarks on x) keeps that difference
  at zero like a hard row, which keeps midline landmarks on the midline.
* ⚠ **Translation anchor** (the digest: every row is a difference, so each
  axis is free up to a shift and an SVD returns the minimum-norm one, which
  moves the head): one extra row per axis keeps the mean of the anchor
  landmarks (the caller's choice: the tragia, where the Frankfort frame's
  origin lies between the porions) where it was.

The least-squares solve uses the SVD with singular values below
σ_max / :data:`CONDITION_NUMBER` dropped (Numerical Recipes' svbksb
practice; Kähler "clamps" to a prescribed condition number without giving
it).  The matrix depends only on which pairs are constrained, not on the
targets, so its pseudo-inverse is computed once per axis and every
re-linearisation is a matrix-vector product.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

#: singular values below σ_max / this are dropped.  With the translation anchored the
#: reference heads' systems have condition numbers of ~2e2 (nearby pairs) to ~1e3 (a
#: landmark tied by one long soft pair only); 1e6 keeps every such direction and still
#: drops exact dependencies (σ ~ 1e-13 σ_max): a 0.01 mm inconsistency in the targets
#: cannot be amplified beyond 1e4 mm · 1e-6 = 0.01 mm per unit of σ_max.
CONDITION_NUMBER = 1e6
#: the Euclidean re-linearisation stops when no landmark moves more than this (mm) ...
TOLERANCE_MM = 1e-4
#: ... or after this many rounds
MAX_ROUNDS = 100
#: weight of a hard row.  Eliminating λ gives a soft pair with little extent on an axis a
#: weight near 1 (two landmarks at the same height keep their height difference), which
#: would weigh as much as a target; Kähler's intent ("errors in q weigh far more than
#: errors in λ, so the hard constraints are met closely") needs the targets heavier:
#: at 10 a hard row outweighs a zero-extent soft pair 100 : 1 in the squared residual
HARD_WEIGHT = 10.0
#: weight of the anchor row (it is consistent with every other row, so any weight > 0
#: fixes the translation; a large one keeps it exact against the soft rows' pull)
ANCHOR_WEIGHT = 100.0
AXES = ("x", "y", "z")


@dataclass(frozen=True)
class Constraint:
    """A target on the landmark pair (a, b): their Euclidean distance, or q_a − q_b on one axis.

    ``axis`` is ``None`` for a Euclidean distance (``target`` ≥ 0, mm) or
    0, 1, 2 for x, y, z (``target`` signed, mm: the coordinate of ``a``
    minus that of ``b``).
    """

    a: int
    b: int
    target: float
    axis: int | None = None
    label: str = ""


@dataclass(frozen=True)
class SoftPair:
    """A pair whose difference on ``axes`` should scale with the global factor."""

    a: int
    b: int
    axes: tuple[int, ...] = (0, 1, 2)
    label: str = ""


@dataclass(frozen=True)
class GrowthSolution:
    """The solved landmarks and how well each constraint is met.

    Attributes
    ----------
    points : (N, 3) new landmark positions (mm, same frame as the input)
    hard_residuals : (H,) achieved − target for each hard constraint (mm)
    soft_factors : list of (pair, axis, λ) — each soft pair's achieved scale factor
    rounds : int  — Euclidean re-linearisation rounds used
    dropped_singular_values : tuple of int per axis (dependent directions removed)
    condition : tuple of float per axis (σ_max / σ_min of the kept spectrum)
    """

    points: np.ndarray
    hard_residuals: np.ndarray
    soft_factors: tuple[tuple[int, int, float], ...]
    rounds: int
    dropped_singular_values: tuple[int, ...]
    condition: tuple[float, ...]


def nearby_pairs(points: np.ndarray, k: int = 4) -> list[tuple[int, int]]:
    """Each landmark with its ``k`` nearest others (Kähler's "nearby landmarks"; the rule is ours).

    The digest notes the seeds leave the neighbour rule open.  k = 4 gives
    ~2k pairs per landmark (the relation is symmetrised), about 2.5 soft
    pairs per landmark per axis — Kähler's ≈100 soft constraints per axis for
    his 44 points.
    """
    pts = np.asarray(points, float)
    n = len(pts)
    if n < 2:
        return []
    kk = min(k + 1, n)
    _, idx = cKDTree(pts).query(pts, k=kk)
    pairs = {(min(i, int(j)), max(i, int(j))) for i in range(n) for j in idx[i, 1:] if j != i}
    return sorted(pairs)


def _rows(
    n: int,
    axis: int,
    hard: Sequence[Constraint],
    soft: Sequence[SoftPair],
    current: np.ndarray,
    anchor: Sequence[int],
) -> tuple[np.ndarray, list[tuple[str, int, float]]]:
    """The weighted difference matrix of one axis and a description of each row."""
    rows: list[np.ndarray] = []
    what: list[tuple[str, int, float]] = []  # (kind, index into hard/soft, weight)
    for i, c in enumerate(hard):
        if c.axis is None or c.axis == axis:
            r = np.zeros(n)
            r[c.a] += HARD_WEIGHT
            r[c.b] -= HARD_WEIGHT
            rows.append(r)
            what.append(("hard", i, HARD_WEIGHT))
    for i, p in enumerate(soft):
        if axis in p.axes:
            d = current[p.a, axis] - current[p.b, axis]
            w = 1.0 / np.sqrt(1.0 + d * d)
            r = np.zeros(n)
            r[p.a] += w
            r[p.b] -= w
            rows.append(r)
            what.append(("soft", i, w))
    r = np.zeros(n)
    r[list(anchor)] = ANCHOR_WEIGHT / len(anchor)
    rows.append(r)
    what.append(("anchor", -1, ANCHOR_WEIGHT))
    return np.array(rows), what


_PINV: dict[bytes, tuple[np.ndarray, int, float]] = {}


def _pinv(matrix: np.ndarray) -> tuple[np.ndarray, int, float]:
    """Clamped pseudo-inverse, dropped directions, kept condition number (cached per matrix:
    re-solves with other targets, a sequence of ages, reuse it)."""
    import hashlib

    key = (
        hashlib.sha1(np.ascontiguousarray(matrix).tobytes()).digest() + repr(matrix.shape).encode()
    )
    hit = _PINV.get(key)
    if hit is not None:
        return hit
    # a few-hundred-row SVD takes ~3.5 ms on one thread; OpenBLAS's own threads on a
    # busy 2-core machine made it take up to 3 s (the caller limits them)
    u, sv, vt = np.linalg.svd(matrix, full_matrices=False)
    keep = sv >= sv[0] / CONDITION_NUMBER
    inv = np.zeros_like(sv)
    inv[keep] = 1.0 / sv[keep]
    out = ((vt.T * inv) @ u.T, int((~keep).sum()), float(sv[0] / sv[keep][-1]))
    if len(_PINV) >= 48:
        _PINV.pop(next(iter(_PINV)))
    _PINV[key] = out
    return out


def solve_landmarks(
    points: np.ndarray,
    hard: Sequence[Constraint],
    soft: Sequence[SoftPair],
    scale: float,
    anchor: Sequence[int],
) -> GrowthSolution:
    """New positions of ``points`` (N, 3; mm) meeting ``hard`` and following ``scale`` elsewhere.

    ``anchor`` lists the landmarks whose mean stays where it is (the
    translation anchor).  See the module docstring for the method.
    """
    from workbench.core.tps import single_threaded_blas

    # small dense products only: OpenBLAS threads on a busy 2-core machine slow them 10-100x
    with single_threaded_blas():
        return _solve(points, hard, soft, scale, anchor)


def _solve(
    points: np.ndarray,
    hard: Sequence[Constraint],
    soft: Sequence[SoftPair],
    scale: float,
    anchor: Sequence[int],
) -> GrowthSolution:
    p = np.asarray(points, float)
    n = len(p)
    if not anchor:
        raise ValueError("the growth solve needs at least one anchor landmark")
    for c in hard:
        if c.a == c.b or not (0 <= c.a < n and 0 <= c.b < n):
            raise ValueError(f"constraint {c.label or (c.a, c.b)} names invalid landmarks")
        if c.axis is None and not c.target > 0:
            raise ValueError(f"constraint {c.label or (c.a, c.b)}: a distance must be > 0")
    centre = p[list(anchor)].mean(axis=0)
    systems = []
    for axis in range(3):
        matrix, what = _rows(n, axis, hard, soft, p, anchor)
        pinv, dropped, cond = _pinv(matrix)
        systems.append((pinv, what, dropped, cond))

    # the right-hand sides: constant rows once, the Euclidean rows' directions per round
    euclid = np.array([i for i, c in enumerate(hard) if c.axis is None], dtype=np.int64)
    ea = np.array([hard[i].a for i in euclid], dtype=np.int64)
    eb = np.array([hard[i].b for i in euclid], dtype=np.int64)
    lengths = np.array([hard[i].target for i in euclid], dtype=float)
    first = p[ea] - p[eb]
    plans = []
    for axis, (pinv, what, _, _) in enumerate(systems):
        fixed = np.zeros(len(what))
        rows_e: list[int] = []
        cols_e: list[int] = []
        where = {int(i): k for k, i in enumerate(euclid)}
        for r, (kind, i, w) in enumerate(what):
            if kind == "hard":
                if hard[i].axis is None:
                    rows_e.append(r)
                    cols_e.append(where[i])
                else:
                    fixed[r] = w * hard[i].target
            elif kind == "soft":
                sp = soft[i]
                fixed[r] = w * scale * (p[sp.a, axis] - p[sp.b, axis])
            else:
                fixed[r] = w * centre[axis]
        plans.append((pinv, fixed, np.array(rows_e, np.int64), np.array(cols_e, np.int64)))

    q = p.copy()
    rounds = 0
    while rounds < MAX_ROUNDS:
        rounds += 1
        # Kähler's linearisation: keep each pair's current direction, scale it to L
        v = q[ea] - q[eb]
        norm = np.linalg.norm(v, axis=1)
        small = norm < 1e-9
        v[small] = first[small]
        norm[small] = np.linalg.norm(first[small], axis=1)
        along = HARD_WEIGHT * lengths[:, None] * v / np.maximum(norm, 1e-12)[:, None]
        new = np.empty_like(q)
        for axis, (pinv, fixed, at_rows, at_cols) in enumerate(plans):
            rhs = fixed.copy()
            rhs[at_rows] = along[at_cols, axis]
            new[:, axis] = pinv @ rhs
        step = float(np.abs(new - q).max())
        q = new
        if step < TOLERANCE_MM:
            break

    residuals = np.array(
        [
            (np.linalg.norm(q[c.a] - q[c.b]) if c.axis is None else q[c.a, c.axis] - q[c.b, c.axis])
            - c.target
            for c in hard
        ]
    )
    factors = []
    for s in soft:
        for axis in s.axes:
            d = p[s.a, axis] - p[s.b, axis]
            r = q[s.a, axis] - q[s.b, axis]
            factors.append((s.a, s.b, float((scale + d * r) / (1.0 + d * d))))
    return GrowthSolution(
        q,
        residuals,
        tuple(factors),
        rounds,
        tuple(s[2] for s in systems),
        tuple(s[3] for s in systems),
    )


def arc_sagitta(chord: float, arc: float) -> float:
    """Height of the circle segment with ``chord`` and ``arc`` length (mm; Kähler §8.5.3).

    Solves arc = 2Rθ, chord = 2R·sin θ for θ (sin θ / θ = chord/arc, by
    Newton's method), then the sagitta h = R(1 − cos θ).  An arc no longer
    than its chord is flat (h = 0).
    """
    if chord <= 0 or arc <= chord:
        return 0.0
    ratio = chord / arc
    # sin θ/θ = ratio on (0, π); start from the series 1 − θ²/6 and refine
    theta = min(np.sqrt(6.0 * (1.0 - ratio)), np.pi - 1e-6)
    for _ in range(50):
        f = np.sin(theta) / theta - ratio
        df = (theta * np.cos(theta) - np.sin(theta)) / (theta * theta)
        step = f / df
        theta = float(np.clip(theta - step, 1e-9, np.pi - 1e-9))
        if abs(step) < 1e-12:
            break
    radius = arc / (2.0 * theta)
    return float(radius * (1.0 - np.cos(theta)))


def arc_length(chord: float, sagitta: float) -> float:
    """Length of the circle arc over ``chord`` with height ``sagitta`` (mm)."""
    if chord <= 0:
        return 0.0
    if sagitta <= 1e-12:
        return float(chord)
    radius = (chord * chord / 4.0 + sagitta * sagitta) / (2.0 * sagitta)
    theta = np.arcsin(min(1.0, chord / (2.0 * radius)))
    if sagitta > radius:  # more than a half circle
        theta = np.pi - theta
    return float(2.0 * radius * theta)
