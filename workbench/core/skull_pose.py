"""Orientation of a bone surface on the reference cranium, from the bone alone (issue 28).

Units mm.  The result maps **target (input) coordinates into the reference's
head frame** (x to the subject's left, y up, z toward the face, Frankfort
Horizontal at y = 0), as :func:`workbench.core.rigid_search.search_pose`
does for hints and seed landmarks; this module is the search used when the
user gives neither.

A bone mesh from another program comes in any file axes, mirrored or not,
with or without its mandible (closed, open, pushed, detached, missing), the
C-spine and hyoid, pins, a tube, a head holder, a cut vault or a defect.
The search is built so that none of these can win against the cranium:

* **the cranium alone orients**: the reference is the cranium with its
  upper teeth; the mandible is posed afterwards on its own
  (:mod:`workbench.services.registration.skull_registration`), so an open or missing jaw
  cannot pull the cranium's pitch;
* **scored both ways**: every pose is judged by how much of the target lies
  on the reference (*forward*: extra anatomy costs a bounded miss) *and* how
  much of the reference finds target bone (*backward*: a vault pitched onto
  a dome still leaves the reference's face bare).  The forward score alone
  has a second basin about 40° forward on real skulls, where the long vault
  of a real cranium lies better on the reference's dome; the backward score
  does not (VHP female: the face term 0.32 at the true pitch, 0.45 there);
* **refined both ways**: the ICP takes pairs in both directions (rigid, at
  the scale the skull widths give), so it cannot slide from the right pitch
  into the forward score's other basin;
* **independent of the file's axes**: the target is first put into its own
  principal frame (axes signed by the third moments), where its distance
  grid is built and the symmetry-plane directions are tried, so turning the
  file does not change which planes, turns and grid cells are seen;
* **candidates** as in the general search: the target's bilateral symmetry
  planes, both sides, every turn about the plane normal and in-plane
  shifts; the best distinct poses are refined and ranked, and the runners-up
  are returned (:attr:`SkullPoseResult.candidates`) so that later evidence
  (a mandible found, the registration's own self-check) can weigh them.

Deterministic: seeded samples, no data-dependent random choices.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.mesh import Mesh, concatenate
from workbench.core.rigid_search import (
    FLIP,
    SCALE_RANGE,
    PoseResult,
    _angle_deg,
    _Cloud,
    _exposed,
    _Grid,
    _rotate_normals,
    _width_scale,
    hint_rotation,
    nearest_agreeing,
    plane_placements,
    rigid_motion,
    surface_samples,
    symmetry_planes,
)

#: σ of the robust loss that ranks the refined poses (mm): wide enough that a real skull
#: whose shape differs from the reference's by a few mm still counts as matched
RANK_SIGMA_MM = 6.0
#: jaw openings (degrees about the jaw axis) the forward reference's mandible is swept over
SWEEP_DEG = (-5.0, 5.0, 15.0, 25.0, 35.0)
#: the reference's facial skeleton, scored backward: head frame z above / y below (mm)
FACE_Z_MM = 25.0
FACE_TOP_MM = 60.0
#: σ of the ICP weights, wide to narrow (mm); each is iterated to convergence (CONVERGED, in
#: degrees and mm per round) or ICP_ROUNDS rounds
ICP_SIGMAS_MM = (20.0, 12.0, 8.0, 5.0, 3.5)
ICP_ROUNDS = 15
CONVERGED = 0.05
#: reference samples used for the backward term of the pose scan
SCAN_REFERENCE_SAMPLES = 400
#: poses of the scan refined by ICP
REFINED = 10
#: the starts' ICP stops after the first COARSE_WIDTHS widths; the best FINISHED distinct
#: ones go on through the narrow widths
COARSE_WIDTHS = 2
FINISHED = 4
#: distinct candidates returned beside the winner
KEPT = 3
DISTINCT_DEG = 20.0
DISTINCT_MM = 20.0


@dataclass(frozen=True)
class Candidate:
    """One refined pose (target → reference) and its scores (0 best, 1 worst)."""

    matrix: np.ndarray
    cost: float
    forward: float
    backward: float


@dataclass(frozen=True)
class SkullPoseResult:
    """The search's ranked distinct candidates, best first (see the module docstring)."""

    candidates: tuple[Candidate, ...]
    mirrored: bool
    #: the handedness came from a hint's ``left``
    hinted_handedness: bool = False
    #: unit normal of the target's own best bilateral-symmetry plane (input frame) and its
    #: loss (0: every sample has its mirror image on the bone)
    symmetry_normal: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    symmetry_loss: float = float("nan")

    @property
    def best(self) -> Candidate:
        return self.candidates[0]

    @property
    def margin(self) -> float:
        """Cost of the best distinct runner-up minus the winner's (large = a clear call)."""
        if len(self.candidates) < 2:
            return float("inf")
        return self.candidates[1].cost - self.candidates[0].cost


def canonical_frame(points: np.ndarray) -> np.ndarray:
    """``(4, 4)`` proper rigid map of ``points`` into their own principal frame.

    Centred on the mean, axes along the principal directions (largest
    first), each axis pointing the way its third moment is positive; the
    third axis completes a right-handed frame.  Turning or shifting the
    points turns the frame with them, so anything computed in it does not
    depend on the file's axes.
    """
    c = points.mean(axis=0)
    x = points - c
    _, _, vt = np.linalg.svd(x, full_matrices=False)
    for i in range(2):
        if np.sum((x @ vt[i]) ** 3) < 0:
            vt[i] = -vt[i]
    vt[2] = np.cross(vt[0], vt[1])
    m = np.eye(4)
    m[:3, :3] = vt
    m[:3, 3] = -vt @ c
    return m


def _map(cloud: _Cloud, m: np.ndarray) -> _Cloud:
    return _Cloud(cloud.points @ m[:3, :3].T + m[:3, 3], cloud.normals @ m[:3, :3].T)


def _spread(cloud: _Cloud, n: int) -> _Cloud:
    """About ``n`` samples spread evenly over the cloud (one per cell of a fitted grid)."""
    span = np.ptp(cloud.points, axis=0).prod()
    cell = (span / max(n, 1)) ** (1 / 3)
    for _ in range(8):
        key = np.floor(cloud.points / cell).astype(np.int64)
        _, first = np.unique(key, axis=0, return_index=True)
        if len(first) <= 1.3 * n:
            break
        cell *= 1.2
    first = np.sort(first)
    return _Cloud(cloud.points[first], cloud.normals[first])


def _robust(d: np.ndarray, ok: np.ndarray, sigma: float) -> np.ndarray:
    return np.where(ok, 1.0 - np.exp(-0.5 * (d / sigma) ** 2), 1.0)


def _grid_loss(grid: _Grid, pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """Mean robust loss of points ``(..., n, 3)`` looked up on ``grid`` (its own σ)."""
    return grid.loss(pts, nrm)


def _scan_plane(
    ref_grid: _Grid,
    own_grid: _Grid,
    small: _Cloud,
    ref_small: _Cloud,
    u: np.ndarray,
    d: float,
    centre: np.ndarray,
    scale: float,
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """Poses putting the plane ``u · x = d`` on x = 0, both sides and every turn, scored both
    ways on the distance grids; one best in-plane shift per (side, turn)."""
    out = []
    for _, r, ts, p, n in plane_placements(small, u, d, centre, scale):
        fwd = ref_grid.loss(p[None] + ts[:, None], np.broadcast_to(n, (len(ts),) + n.shape))
        # backward: the reference samples mapped into the target's frame (r⁻¹ = rᵀ/s²)
        q = (ref_small.points[None] - ts[:, None]) @ r / scale**2
        qn = ref_small.normals @ r / scale
        bwd = own_grid.loss(q, np.broadcast_to(qn, q.shape))
        cost = 0.5 * (fwd + bwd)
        k = int(np.argmin(cost))
        out.append((float(cost[k]), r, ts[k]))
    out.sort(key=lambda x: x[0])
    return out


def _scan_shifts(
    ref_grid: _Grid,
    own_grid: _Grid,
    small: _Cloud,
    face_small: _Cloud,
    r: np.ndarray,
    centre: np.ndarray,
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """One rotation (a hint's) at every shift of a 3-D grid around the centred pose, scored
    both ways as :func:`_scan_plane` scores a turn."""
    scale = abs(np.linalg.det(r)) ** (1 / 3)
    p = small.points @ r.T
    t0 = centre - p.mean(axis=0)
    steps = np.arange(-40.0, 40.1, 8.0)
    ts = t0 + np.array(list(itertools.product(steps, repeat=3)))
    n = small.normals @ r.T / scale
    fwd = ref_grid.loss(p[None] + ts[:, None], np.broadcast_to(n, (len(ts),) + n.shape))
    q = (face_small.points[None] - ts[:, None]) @ r / scale**2
    qn = face_small.normals @ r / scale
    bwd = own_grid.loss(q, np.broadcast_to(qn, q.shape))
    cost = 0.5 * (fwd + bwd)
    return [(float(cost[k]), r, ts[k]) for k in np.argsort(cost)[:REFINED]]


def _distinct(
    cands: list[tuple[float, np.ndarray, np.ndarray]], n: int
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    kept: list[tuple[float, np.ndarray, np.ndarray]] = []
    for c, r, t in cands:
        if all(
            _angle_deg(r, r2) > DISTINCT_DEG or np.linalg.norm(t - t2) > DISTINCT_MM
            for _, r2, t2 in kept
        ):
            kept.append((c, r, t))
        if len(kept) == n:
            break
    return kept


def _distinct_poses(
    poses: list[tuple[float, np.ndarray, np.ndarray]], n: int
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """The first ``n`` of ``poses`` (cost, linear part, shift; best first) that differ from
    each other by more than :data:`DISTINCT_DEG` or :data:`DISTINCT_MM`."""
    return _distinct(poses, n)


class _TwoWay:
    """Nearest agreeing neighbours in both directions: target samples on the forward reference
    samples, and the backward reference samples (the facial skeleton) on the posed target."""

    def __init__(self, ref: _Cloud, back: _Cloud, target: _Cloud):
        self.ref = ref
        self.back = back
        self.target = target
        self.ref_tree = cKDTree(ref.points)

    def pairs(self, lin: np.ndarray, t: np.ndarray) -> tuple:
        """Forward and backward matches of the target posed by ``(lin, t)``."""
        pts = self.target.points @ lin.T + t
        nrm = _rotate_normals(lin, self.target.normals)
        fd, fj, fok = nearest_agreeing(self.ref_tree, self.ref.normals, pts, nrm)
        bd, bj, bok = nearest_agreeing(cKDTree(pts), nrm, self.back.points, self.back.normals)
        return pts, (fd, fj, fok), (bd, bj, bok)

    def scores(self, lin: np.ndarray, t: np.ndarray, sigma: float) -> tuple[float, float]:
        _, (fd, _, fok), (bd, _, bok) = self.pairs(lin, t)
        return float(_robust(fd, fok, sigma).mean()), float(_robust(bd, bok, sigma).mean())


def _scale_step(
    src: np.ndarray, dst: np.ndarray, w: np.ndarray, current: float
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted uniform scale and shift ``dst ≈ s src + t`` (the total scale ``current · s``
    kept within ``SCALE_RANGE``), as a (3, 3) linear part and a shift."""
    ws = w / w.sum()
    cs, cd = ws @ src, ws @ dst
    a, b = src - cs, dst - cd
    k = float(ws @ (a * b).sum(axis=1)) / max(float(ws @ (a * a).sum(axis=1)), 1e-12)
    k = float(np.clip(current * k, *SCALE_RANGE)) / current
    return k * np.eye(3), cd - k * cs


def two_way_icp(
    match: _TwoWay,
    lin: np.ndarray,
    t: np.ndarray,
    *,
    sigmas: tuple[float, ...] = ICP_SIGMAS_MM,
    rounds: int = ICP_ROUNDS,
    scale_only: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Robust rigid ICP on pairs in both directions (keeps ``lin``'s scale and handedness).

    ``scale_only``: the turn is held and a uniform scale (about the pairs' centre,
    within ``SCALE_RANGE`` overall) and a shift are fitted instead.

    Each round takes every target sample's nearest agreeing reference sample
    and every backward reference sample's nearest agreeing target sample,
    weights the pairs by a Welsch kernel of width σ, and solves one weighted
    rigid motion for all of them (each direction carrying half the weight).
    σ goes through ``sigmas``, wide to narrow, and each width is iterated
    until a round turns and moves the pose less than :data:`CONVERGED`
    (degrees, mm) or ``rounds`` rounds: the wide widths decide the basin, the
    narrow ones the detail.  (One round per width left starts 5° apart on a
    CT with the vault cut off, whose objective is flat.)  The scale is the
    start's (the skull widths, :func:`~workbench.core.rigid_search._width_scale`) unless
    ``scale_only``:
    fitted in the ICP, it slid with the pose on such a CT — two hinted runs on
    headsq's bone at 126 and 300 HU ended 12° and 6 % apart, with the scale
    held 2° — and the dense registration's affine stage takes up the size.
    """
    for sigma in sigmas:
        for _ in range(rounds):
            pts, (fd, fj, fok), (bd, bj, bok) = match.pairs(lin, t)
            wf = np.where(fok, np.exp(-0.5 * (fd / sigma) ** 2), 0.0)
            wb = np.where(bok, np.exp(-0.5 * (bd / sigma) ** 2), 0.0)
            if wf.sum() + wb.sum() < 1e-9:
                return lin, t
            wf = wf / max(wf.sum(), 1e-9)
            wb = wb / max(wb.sum(), 1e-9)
            src = np.vstack([pts, pts[bj]])
            dst = np.vstack([match.ref.points[fj], match.back.points])
            w = np.concatenate([wf, wb])
            if scale_only:
                r, tr = _scale_step(src, dst, w, abs(np.linalg.det(lin)) ** (1 / 3))
            else:
                r, tr = rigid_motion(src, dst, w)
            lin, t = r @ lin, r @ t + tr
            turn = (  # a polish's step changes the scale (in %), a rigid one turns (degrees)
                100.0 * abs(r[0, 0] - 1.0)
                if scale_only
                else float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0))))
            )
            shift = float(np.linalg.norm((r - np.eye(3)) @ pts.mean(axis=0) + tr))
            if turn < CONVERGED and shift < CONVERGED:
                break
    return lin, t


def swept_jaw(mandible: Mesh, axis_point: np.ndarray, axis_dir: np.ndarray) -> Mesh:
    """The mandible (with its lower teeth) at every opening of :data:`SWEEP_DEG` about the jaw
    axis, as one surface: the target's jaw finds reference bone at any opening it came in."""
    d = np.asarray(axis_dir, float)
    d = d / np.linalg.norm(d) * (1.0 if d[0] >= 0 else -1.0)
    k = np.array([[0, -d[2], d[1]], [d[2], 0, -d[0]], [-d[1], d[0], 0]])
    pieces = []
    for deg in SWEEP_DEG:
        th = np.radians(deg)
        r = np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * k @ k
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = r, axis_point - r @ axis_point
        pieces.append(mandible.transformed(m))
    return concatenate(pieces)


def face_mask(points: np.ndarray) -> np.ndarray:
    """Reference samples (head frame) on the facial skeleton: in front of :data:`FACE_Z_MM`
    and below :data:`FACE_TOP_MM` (brow, orbits, nasal bones, zygomas, maxilla, upper teeth)."""
    return (points[:, 2] > FACE_Z_MM) & (points[:, 1] < FACE_TOP_MM)


def search_skull_pose(
    target: Mesh,
    cranium: Mesh,
    mandible: Mesh,
    jaw_axis: np.ndarray,
    *,
    hint: tuple | None = None,
    mirror: str = "no",
    n_samples: int = 1500,
    seed: int = 0,
) -> SkullPoseResult:
    """Ranked distinct similarities mapping ``target`` (input frame, mm) onto the reference.

    ``cranium`` (with the upper teeth) and ``mandible`` (with the lower
    teeth) are the reference parts in the head frame and ``jaw_axis`` the
    ``(2, 3)`` point and direction of its jaw (condylar) axis.  ``hint``
    (anterior, superior[, left]) in input coordinates replaces the scan of
    turns by the one rotation it gives (its shifts are still searched, and
    the refinement is the same).  ``mirror``: ``"no"`` keeps the file's
    handedness (a skull's shape cannot tell a mirrored file), ``"yes"``
    reads it reflected; a hint with ``left`` decides it.
    """
    if mirror not in ("no", "yes"):
        raise ValueError("mirror must be 'no' or 'yes'")
    if hint is not None:
        rot, hinted_mirror = hint_rotation(hint[0], hint[1], hint[2] if len(hint) > 2 else None)
        if len(hint) > 2 and hint[2] is not None:
            mirror = "yes" if hinted_mirror else "no"
    target = target.outward()
    rng = np.random.default_rng(seed)
    forward_ref = concatenate([cranium, swept_jaw(mandible, *np.asarray(jaw_axis, float))])
    ref = surface_samples(forward_ref, 8 * n_samples, rng)
    cran = surface_samples(cranium, 8 * n_samples, rng)
    face = _Cloud(*(x[face_mask(cran.points)] for x in (cran.points, cran.normals)))
    everything = surface_samples(target, 4 * n_samples, rng)
    exposed = _exposed(target, everything)
    dense = surface_samples(target, 8 * n_samples, rng)
    canon = canonical_frame(everything.points)
    if mirror == "yes":
        flip = np.eye(4)
        flip[:3, :3] = FLIP
        canon = flip @ canon
    exposed_c = _map(exposed, canon)
    small = _Cloud(exposed_c.points[:150], exposed_c.normals[:150])
    cloud = _Cloud(exposed_c.points[:n_samples], exposed_c.normals[:n_samples])
    own = _Grid(_map(dense, canon))
    own_out = _Grid(exposed_c)
    ref_grid = _Grid(ref)
    face_small = _spread(face, SCAN_REFERENCE_SAMPLES)
    cands: list[tuple[float, np.ndarray, np.ndarray]] = []
    centre = cran.points.mean(axis=0)
    planes = symmetry_planes(cloud, own)
    if hint is None:
        for _, u, d in planes:
            s0 = _width_scale(cran, cloud, u)
            cands += _scan_plane(ref_grid, own_out, small, face_small, u, d, centre, s0)
    else:
        # the hint's map of input directions onto the head axes (reflected for a mirrored
        # file), seen from the canonical frame (which holds that reflection too)
        r = (FLIP @ rot if mirror == "yes" else rot) @ np.linalg.inv(canon)[:3, :3]
        r = _width_scale(cran, cloud, r[0]) * r
        cands = _scan_shifts(ref_grid, own_out, small, face_small, r, centre)
    cands.sort(key=lambda x: x[0])
    match = _TwoWay(_spread(ref, 3 * n_samples), _spread(face, n_samples), cloud)
    # every distinct start through the wide widths, the best few through the narrow ones
    coarse = []
    for _, lin, t in _distinct(cands, REFINED):
        lin, t = two_way_icp(match, lin, t, sigmas=ICP_SIGMAS_MM[:COARSE_WIDTHS])
        fwd, bwd = match.scores(lin, t, RANK_SIGMA_MM)
        coarse.append((0.5 * (fwd + bwd), lin, t))
    coarse.sort(key=lambda x: x[0])
    refined = []
    for _, lin, t in _distinct_poses(coarse, FINISHED):
        lin, t = two_way_icp(match, lin, t, sigmas=ICP_SIGMAS_MM[COARSE_WIDTHS:])
        # the turn found at the widths' scale, then the size and place polished with the
        # turn held (a scale free during the turn's ICP slides with the pose)
        lin, t = two_way_icp(match, lin, t, sigmas=ICP_SIGMAS_MM[-2:], scale_only=True)
        fwd, bwd = match.scores(lin, t, RANK_SIGMA_MM)
        refined.append((0.5 * (fwd + bwd), fwd, bwd, lin, t))
    refined.sort(key=lambda x: x[0])
    kept: list[Candidate] = []
    canon_inv = np.linalg.inv(canon)
    for cost, fwd, bwd, lin, t in refined:
        # two poses differ by their turn, or by where they put the bone's centre (the
        # canonical origin): compared as matrices of input coordinates, a turn of a degree
        # would move the shift of a file placed far from its origin by tens of mm
        seen = [k.matrix @ canon_inv for k in kept]
        if all(
            _angle_deg(lin, k[:3, :3]) > DISTINCT_DEG or np.linalg.norm(t - k[:3, 3]) > DISTINCT_MM
            for k in seen
        ):
            m = np.eye(4)
            m[:3, :3], m[:3, 3] = lin, t
            kept.append(Candidate(m @ canon, cost, fwd, bwd))  # input → canonical → reference
        if len(kept) == KEPT:
            break
    handed = hint is not None and len(hint) > 2 and hint[2] is not None
    normal = np.linalg.inv(canon)[:3, :3] @ planes[0][1]
    return SkullPoseResult(
        tuple(kept), mirror == "yes", handed, normal / np.linalg.norm(normal), planes[0][0]
    )


def as_pose_result(found: SkullPoseResult, method: str = "search") -> PoseResult:
    """The winner as a :class:`~workbench.core.rigid_search.PoseResult` (runners-up as its
    alternatives), for the registration steps that take one; ``method`` is ``"search"`` or
    ``"hint"``."""
    handedness = "hint" if method == "hint" and found.hinted_handedness else "assumed"

    def one(c: Candidate, alts: tuple[PoseResult, ...] = ()) -> PoseResult:
        scale = float(abs(np.linalg.det(c.matrix[:3, :3])) ** (1 / 3))
        return PoseResult(
            c.matrix,
            scale,
            found.mirrored,
            c.cost,
            1.0 - c.forward,
            handedness,
            float("nan"),
            method,
            alts,
        )

    alts = tuple(one(c) for c in found.candidates[1:])
    return one(found.best, alts)
