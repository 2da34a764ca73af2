"""Orientation of a target surface on a reference surface: robust multi-start similarity search.

Units mm.  The result maps **target (input) coordinates into the
reference's frame** (for the reference head: the Frankfort head frame, x to
the subject's left, y up, z forward).

Why a new search (issue 11): a target skull can lack its mandible or its
vault, carry a defect, the C-spine, a tube, fiducial pins or the CT table,
and come in any file axes, any handedness.  So:

* the score runs **from the target to the reference only**: every target
  sample looks for the reference surface and scores a robust (Welsch)
  loss ``1 − exp(−d²/2σ²)`` that saturates at 1, so extra anatomy, debris
  and the inner surfaces a CT shows (the inner table, sinus and nasal
  walls, which an outer reference surface lacks) cost the same as any miss
  whatever their distance, and a missing part of the target costs nothing;
* a match counts only when the **surface normals agree** (cos >
  :data:`MIN_COS`): the maxilla cannot lock onto the reference mandible
  from behind, glabella cannot settle on the inner wall of the frontal
  sinus;
* **starts are compared at equal scale** (the input is in mm; scale is
  fitted last, on the overlap of both surfaces in both directions, so a
  partial target cannot shrink into the reference);
* starts from **bilateral symmetry**: a skull is symmetric, so the target's
  own symmetry plane is found first (:func:`symmetry_planes`: every
  direction of a fine half-sphere as the plane normal, the target's samples
  reflected across it and looked up on the target's own distance grid —
  independent of the reference and of how much of the skull is missing).
  The plane goes to x = 0; both sides and every turn about its normal
  (:data:`TURN_STEP_DEG`) with in-plane shifts are scored on a distance grid
  of the reference (:class:`_Grid`); the best distinct poses are refined by
  ICP and ranked with how well the reference's facial skeleton is covered
  (:func:`_face_coverage_loss`: a vault fits a dome in many pitches, a face
  does not).  With an orientation hint only its rotation is tried (at
  several offsets); three or more seed landmarks give the start directly;
* **handedness**: with ``mirror="auto"`` every start is also tried on the
  reflected target; a reflected reading wins only when its cost is lower by
  :data:`MIRROR_MARGIN` — a skull is nearly symmetric, so usually the shape
  cannot tell, which the result says (``handedness``).

Deterministic: samples come from a seeded generator and every step is
plain linear algebra.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.compiled import numba
from workbench.core.frame import apply_transform
from workbench.core.mesh import Mesh
from workbench.core.threads import query_workers, worker_count

MIN_COS = 0.3
#: σ of the robust loss of the score (mm)
SCORE_SIGMA_MM = 4.0
#: σ of the ICP weights, first round to last, in the wide search and in the refinement (mm)
SEARCH_SIGMA_MM = (25.0, 6.0)
REFINE_SIGMA_MM = (8.0, 3.0)
#: a reflected (or a proper) reading must beat the other by this factor to be believed
MIRROR_MARGIN = 0.85
SCALE_RANGE = (0.8, 1.25)
#: plane normals tried for the symmetry plane (half-sphere, about 6° apart)
PLANE_DIRECTIONS = 400
#: turns about the symmetry-plane normal, and in-plane shifts, of the pose scan
TURN_STEP_DEG = 5.0
PLANE_SHIFTS_MM = tuple(np.arange(-40.0, 40.1, 10.0))
#: poses of the scan refined by ICP, and what counts as another basin
REFINED = 8
#: next-best distinct poses a search returns beside its winner
ALTERNATIVES = 2
DISTINCT_DEG = 20.0
GRID_MM = 4.0
#: reference samples in front of this (head frame z, mm) make up its facial skeleton
FACE_Z_MM = 25.0
FLIP = np.diag([-1.0, 1.0, 1.0])


@dataclass(frozen=True)
class PoseResult:
    """Target → reference similarity found by :func:`search_pose`.

    Attributes
    ----------
    matrix : (4, 4)
        Homogeneous map of target points into the reference frame (a
        reflection included when ``mirrored``).
    scale : float
    mirrored : bool
    cost : float
        Mean robust loss of the target samples (0 = every sample on the
        reference with agreeing normals, 1 = none).
    matched_fraction : float
        Target samples within 3 mm of the reference with agreeing normals.
    handedness : str
        ``"hint"``, ``"seeds"``, ``"shape"`` (the shape decided) or
        ``"assumed"`` (the shape could not tell; the file's own handedness kept).
    mirror_ratio : float
        Cost of the best start of the other handedness / this cost (≥ 1);
        NaN when only one handedness was tried.
    method : str
        ``"search"``, ``"hint"`` or ``"seeds"``.
    alternatives : tuple of PoseResult
        A search's next-best distinct poses (same handedness, more than
        :data:`DISTINCT_DEG` or 20 mm from this one and from each other, best
        first; up to :data:`ALTERNATIVES`), for a caller whose later evidence
        (a mandible found or not) can tell a wrong winner.  Empty for hints
        and seeds.
    """

    matrix: np.ndarray
    scale: float
    mirrored: bool
    cost: float
    matched_fraction: float
    handedness: str
    mirror_ratio: float
    method: str
    alternatives: tuple[PoseResult, ...] = ()

    def apply(self, points: np.ndarray) -> np.ndarray:
        return apply_transform(self.matrix, points)


@dataclass(frozen=True)
class _Cloud:
    points: np.ndarray
    normals: np.ndarray


def surface_samples(mesh: Mesh, n: int, rng: np.random.Generator) -> _Cloud:
    """``n`` area-weighted surface points with their (outward) face normals."""
    areas = mesh.face_areas
    total = float(areas.sum())
    if not total > 0:
        raise ValueError("the surface has no area")
    faces = rng.choice(len(areas), size=n, p=areas / total)
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    w = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
    pts = np.einsum("ij,ijk->ik", w, mesh.vertices[mesh.faces[faces]])
    return _Cloud(pts, mesh.face_normals[faces])


def rotations_24() -> list[np.ndarray]:
    """The 24 proper rotations that map the coordinate axes onto themselves."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[np.arange(3), perm] = signs
            if np.linalg.det(m) > 0:
                out.append(m)
    return out


def _exposed(mesh: Mesh, cloud: _Cloud) -> _Cloud:
    """The samples on the *outer* surface: a ray along the normal leaves the mesh.

    A CT bone surface also holds the inner table of the vault, the walls of
    the sinuses and the nasal cavity; a reference skull is an outer surface
    only, so inner samples would only blur the score.  Falls back to all
    samples when fewer than a quarter are exposed (a mesh with odd winding).
    """
    from workbench.core.raycast import RayCaster

    hits = RayCaster.shared(mesh).first_hits(cloud.points + 0.5 * cloud.normals, cloud.normals)
    out = ~hits.hit
    if out.sum() < len(out) // 4:
        return cloud
    return _Cloud(cloud.points[out], cloud.normals[out])


def principal_axes(points: np.ndarray) -> np.ndarray:
    """Rows: the principal axes of ``points`` (largest spread first), a right-handed set."""
    c = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    if np.linalg.det(vt) < 0:
        vt[2] *= -1
    return vt


def hint_rotation(
    anterior: np.ndarray, superior: np.ndarray, left: np.ndarray | None = None
) -> tuple[np.ndarray, bool]:
    """Rotation of input directions onto the head axes, and whether ``left`` says mirrored.

    Rows of the returned matrix: left, up, forward (in input coordinates).
    """
    ant = np.asarray(anterior, float) / np.linalg.norm(anterior)
    sup = np.asarray(superior, float)
    sup = sup - ant * (sup @ ant)
    sup /= np.linalg.norm(sup)
    lft = np.cross(sup, ant)
    mirrored = left is not None and float(np.dot(lft, left)) < 0
    return np.vstack([lft, sup, ant]), mirrored


class _Grid:
    """Distance (and nearest-surface normal) of the reference on a regular grid.

    Built with an exact Euclidean distance transform of the cells the
    reference samples occupy; a lookup costs one index computation, so
    tens of thousands of poses can be scored in a second.
    """

    def __init__(self, ref: _Cloud, spacing: float = GRID_MM, pad: float = 80.0):
        from scipy import ndimage

        self.spacing = spacing
        self.lo = ref.points.min(axis=0) - pad
        shape = np.ceil((ref.points.max(axis=0) + pad - self.lo) / spacing).astype(int) + 1
        cell = np.floor((ref.points - self.lo) / spacing).astype(int)
        occupied = np.zeros(shape, bool)
        owner = np.zeros(shape, np.int64)
        occupied[tuple(cell.T)] = True
        owner[tuple(cell.T)] = np.arange(len(cell))
        dist, idx = ndimage.distance_transform_edt(~occupied, return_indices=True)
        self.dist = (dist * spacing).astype(np.float32)
        self.normal = ref.normals[owner[tuple(idx)]].astype(np.float32)
        self.shape = np.array(shape)

    def loss(self, pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
        """Mean robust loss over the last-but-one axis of ``pts`` ``(..., n, 3)``.

        ``nrm`` has the shape of ``pts`` or broadcasts to it along the leading
        axes (one set of normals for every pose).
        """
        pts = np.asarray(pts, np.float64)
        nrm = np.asarray(nrm, np.float64)
        lead = pts.shape[:-2]
        p = np.ascontiguousarray(pts.reshape(-1, *pts.shape[-2:]))
        if nrm.ndim == 2 or int(np.prod(nrm.shape[:-2])) == 1 or nrm.strides[0] == 0:
            # one set of normals for every pose (a broadcast view): pass it once
            n = np.ascontiguousarray(nrm.reshape(-1, *nrm.shape[-2:])[:1])
        else:
            n = np.ascontiguousarray(np.broadcast_to(nrm, pts.shape).reshape(p.shape))
        out = _grid_loss(
            self.dist, self.normal, self.lo, float(self.spacing), p, n, 2.0 * SCORE_SIGMA_MM
        )
        return out.reshape(lead)


def _grid_loss_kernel(
    dist: np.ndarray,
    normal: np.ndarray,
    lo: np.ndarray,
    spacing: float,
    pts: np.ndarray,
    nrm: np.ndarray,
    sigma: float,
) -> np.ndarray:
    """Per pose (first axis of ``pts``) the mean robust loss of its points on the grid: the
    nearest grid node's distance, 1 outside the grid or where the normals disagree."""
    n_pose, n = pts.shape[0], pts.shape[1]
    shared = nrm.shape[0] == 1
    out = np.empty(n_pose)
    nx, ny, nz = dist.shape
    for p in range(n_pose):
        q = 0 if shared else p
        total = 0.0
        for i in range(n):
            c0 = int(np.rint((pts[p, i, 0] - lo[0]) / spacing))
            c1 = int(np.rint((pts[p, i, 1] - lo[1]) / spacing))
            c2 = int(np.rint((pts[p, i, 2] - lo[2]) / spacing))
            if c0 < 0 or c1 < 0 or c2 < 0 or c0 >= nx or c1 >= ny or c2 >= nz:
                total += 1.0
                continue
            cos = (
                normal[c0, c1, c2, 0] * nrm[q, i, 0]
                + normal[c0, c1, c2, 1] * nrm[q, i, 1]
                + normal[c0, c1, c2, 2] * nrm[q, i, 2]
            )
            if cos > MIN_COS:
                d = dist[c0, c1, c2] / sigma
                total += 1.0 - np.exp(-0.5 * d * d)
            else:
                total += 1.0
        out[p] = total / n
    return out


if numba is not None:
    _grid_loss = numba.njit(cache=True, nogil=True)(_grid_loss_kernel)
else:  # pragma: no cover - numba is a dependency
    _grid_loss = _grid_loss_kernel


def _fibonacci_hemisphere(n: int) -> np.ndarray:
    """``n`` unit vectors spread evenly over the half-sphere z ≥ 0 (fixed)."""
    i = np.arange(n) + 0.5
    z = i / n
    phi = np.pi * (1 + 5**0.5) * i
    r = np.sqrt(1 - z**2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _reflect(
    points: np.ndarray, normals: np.ndarray, u: np.ndarray, d: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Points and normals reflected across the planes ``u · x = d`` (broadcast over d)."""
    s = points @ u
    p = points[None] - 2.0 * (s[None] - np.asarray(d)[:, None])[..., None] * u
    n = normals - 2.0 * (normals @ u)[:, None] * u
    return p, np.broadcast_to(n, p.shape)


def symmetry_planes(
    cloud: _Cloud, own: _Grid, keep: int = 3
) -> list[tuple[float, np.ndarray, float]]:
    """Best bilateral-symmetry planes ``(loss, unit normal, offset)`` of a target sample cloud.

    Every direction of a fine half-sphere (and the principal axes) is
    tried as the plane normal at offsets around the median of the
    projections; the loss is the robust loss of the reflected samples
    looked up on the target's own distance grid (``own``).  The best
    distinct planes are then polished by small tilts and shifts.
    """
    dirs = np.vstack([_fibonacci_hemisphere(PLANE_DIRECTIONS), principal_axes(cloud.points)])
    offsets = np.arange(-24.0, 24.1, 4.0)
    found = []
    for u in dirs:
        u = u / np.linalg.norm(u)
        shifts = float(np.median(cloud.points @ u)) + offsets
        p, n = _reflect(cloud.points, cloud.normals, u, shifts)
        loss = own.loss(p, n)
        k = int(np.argmin(loss))
        found.append((float(loss[k]), u, float(shifts[k])))
    found.sort(key=lambda x: x[0])
    best: list[tuple[float, np.ndarray, float]] = []
    for c, u, d in found:
        if all(abs(float(u @ u2)) < np.cos(np.radians(15.0)) for _, u2, _ in best):
            best.append((c, u, d))
        if len(best) == keep:
            break
    out = []
    for c, u, d in best:
        for angle, step in ((4.0, 2.0), (2.0, 1.0), (1.0, 0.5)):
            cands = [q @ u for q in _small_rotations(angle)]
            ds = d + np.array([-step, 0.0, step])
            for v in cands:
                p, n = _reflect(cloud.points, cloud.normals, v, ds)
                loss = own.loss(p, n)
                k = int(np.argmin(loss))
                if loss[k] < c:
                    c, u, d = float(loss[k]), v, float(ds[k])
        out.append((c, u, d))
    out.sort(key=lambda x: x[0])
    return out


def _width_scale(ref: _Cloud, cloud: _Cloud, left: np.ndarray) -> float:
    """Provisional scale (reference / target) from the skull widths across the midline.

    The width (2nd to 98th percentile of the samples along the left-right
    axis: zygomas, temporal and parietal bones) barely depends on a missing
    vault or mandible, so the starts of two skulls of different size are
    compared near their common size; the scale is fitted properly after the
    orientation (:func:`_fit_scale`).
    """
    lo, hi = np.percentile(cloud.points @ (left / np.linalg.norm(left)), [2, 98])
    rlo, rhi = np.percentile(ref.points[:, 0], [2, 98])
    return float(np.clip((rhi - rlo) / max(hi - lo, 1e-6), *SCALE_RANGE))


def plane_placements(
    small: _Cloud, u: np.ndarray, d: float, centre: np.ndarray, scale: float = 1.0
) -> Iterator[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Every pose putting the plane ``u · x = d`` on x = 0, both sides and every turn about
    it (:data:`TURN_STEP_DEG`), with a grid of in-plane shifts (:data:`PLANE_SHIFTS_MM`).

    Yields ``(side, r, ts, p, n)``: the side (±1), the linear part (3, 3) at ``scale``, the
    shifts (k, 3), and ``small``'s points and unit normals turned by ``r`` (not shifted).
    """
    b0 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    b0 /= np.linalg.norm(b0)
    offs = np.array(list(itertools.product(PLANE_SHIFTS_MM, repeat=2)))
    for side in (1.0, -1.0):
        a = side * u
        c0 = np.cross(a, b0)
        for th in np.radians(np.arange(0.0, 360.0, TURN_STEP_DEG)):
            b = np.cos(th) * b0 + np.sin(th) * c0
            r = scale * np.vstack([a, b, np.cross(a, b)])
            p = small.points @ r.T
            t0 = centre - p.mean(axis=0)
            ts = np.column_stack(
                [np.full(len(offs), -side * d * scale), t0[1] + offs[:, 0], t0[2] + offs[:, 1]]
            )
            yield side, r, ts, p, small.normals @ r.T / scale


def _plane_poses(
    grid: _Grid, small: _Cloud, u: np.ndarray, d: float, centre: np.ndarray, scale: float = 1.0
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """Poses putting the plane ``u · x = d`` on x = 0: both sides, every turn about it.

    Scored by the reference fit over a grid of in-plane translations;
    returns one best translation per (side, turn).
    """
    out = []
    for _, r, ts, p, n in plane_placements(small, u, d, centre, scale):
        loss = grid.loss(p[None] + ts[:, None], np.broadcast_to(n, (len(ts),) + n.shape))
        k = int(np.argmin(loss))
        out.append((float(loss[k]), r, ts[k]))
    out.sort(key=lambda x: x[0])
    return out


def _distinct(
    cands: list[tuple[float, np.ndarray, np.ndarray]], n: int
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    kept: list[tuple[float, np.ndarray, np.ndarray]] = []
    for c, r, t in cands:
        if all(
            _angle_deg(r, r2) > DISTINCT_DEG or np.linalg.norm(t - t2) > 20.0 for _, r2, t2 in kept
        ):
            kept.append((c, r, t))
        if len(kept) == n:
            break
    return kept


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle of the rotation between two (possibly reflected) orientations."""
    r = a @ b.T
    r = r / np.cbrt(np.linalg.det(r))
    return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0))))


def _small_rotations(angle_deg: float) -> list[np.ndarray]:
    """The identity and rotations by ``angle_deg`` about 13 axes (both ways)."""
    axes = [np.array(a, float) for a in itertools.product((-1, 0, 1), repeat=3) if any(a)]
    axes = [a / np.linalg.norm(a) for a in axes if tuple(-a) > tuple(a)]
    th = np.radians(angle_deg)
    out = [np.eye(3)]
    for a in axes:
        k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
        for sgn in (1.0, -1.0):
            out.append(np.eye(3) + np.sin(sgn * th) * k + (1 - np.cos(th)) * k @ k)
    return out


class _Scorer:
    """Target → reference residuals with the normal test (reference as a dense cloud)."""

    def __init__(self, reference: _Cloud):
        self.ref = reference
        self.tree = cKDTree(reference.points)

    def match(
        self, pts: np.ndarray, nrm: np.ndarray, k: int = 4
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per point: distance to the nearest reference sample with an agreeing normal.

        Returns ``(distance, index, ok)``; ``ok`` is False where none of the
        ``k`` nearest samples agrees (distance is then the plain nearest).
        """
        d, j = self.tree.query(pts, k=k, workers=worker_count())
        cos = np.einsum("ikj,ij->ik", self.ref.normals[j], nrm)
        good = cos > MIN_COS
        first = np.where(good.any(axis=1), good.argmax(axis=1), 0)
        rows = np.arange(len(pts))
        return d[rows, first], j[rows, first], good.any(axis=1)

    def cost(self, pts: np.ndarray, nrm: np.ndarray) -> float:
        d, _, ok = self.match(pts, nrm)
        loss = np.where(ok, 1.0 - np.exp(-0.5 * (d / SCORE_SIGMA_MM) ** 2), 1.0)
        return float(loss.mean())


def _face_coverage_loss(ref: _Cloud, target: _Cloud, lin: np.ndarray, t: np.ndarray) -> float:
    """How badly the reference's facial skeleton is covered by the target at a pose.

    The reference samples in front (head frame z > :data:`FACE_Z_MM`: frontal
    bone, orbits, zygomas, maxilla, teeth, the front of the mandible) look
    for target bone with an agreeing normal; the mean robust loss is
    returned.  A target seen at a wrong pitch — vault on vault, C-spine on
    the chin — leaves the reference face uncovered, which the target →
    reference score alone barely notices because a vault fits a dome in
    many pitches.  Used only to rank the refined candidates.
    """
    face = ref.points[:, 2] > FACE_Z_MM
    pts = target.points @ lin.T + t
    nrm = _rotate_normals(lin, target.normals)
    d, j = cKDTree(pts).query(ref.points[face], k=4)
    cos = np.einsum("ikj,ij->ik", nrm[j], ref.normals[face])
    good = cos > MIN_COS
    first = np.where(good.any(axis=1), good.argmax(axis=1), 0)
    dd = d[np.arange(len(d)), first]
    loss = np.where(good.any(axis=1), 1.0 - np.exp(-0.5 * (dd / SCORE_SIGMA_MM) ** 2), 1.0)
    return float(loss.mean())


def rigid_motion(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted proper rigid motion (R, t) with dst ≈ R src + t (Kabsch)."""
    ws = w / w.sum()
    cs, cd = ws @ src, ws @ dst
    h = (src - cs).T @ ((dst - cd) * ws[:, None])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cd - r @ cs


def nearest_agreeing(
    tree: cKDTree, normals: np.ndarray, pts: np.ndarray, nrm: np.ndarray, k: int = 6
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each of ``pts`` (unit normals ``nrm``), the nearest of the ``k`` nearest points of
    ``tree`` whose normal (``normals``) agrees (cos > :data:`MIN_COS`): its distance, its
    index, and whether any agreed (where none did, the nearest's distance and index)."""
    d, j = tree.query(pts, k=k, workers=query_workers(len(pts)))
    cos = np.einsum("ikj,ij->ik", normals[j], nrm)
    good = cos > MIN_COS
    first = np.where(good.any(axis=1), good.argmax(axis=1), 0)
    rows = np.arange(len(pts))
    return d[rows, first], j[rows, first], good.any(axis=1)


def _icp(
    scorer: _Scorer,
    cloud: _Cloud,
    lin: np.ndarray,
    t: np.ndarray,
    rounds: int,
    seeds: tuple[np.ndarray, np.ndarray] | None = None,
    sigma_mm: tuple[float, float] = REFINE_SIGMA_MM,
) -> tuple[np.ndarray, np.ndarray, float]:
    """Robust (Welsch-weighted), normal-checked rigid ICP keeping ``lin``'s scale and handedness.

    The weight σ shrinks geometrically over the rounds from ``sigma_mm[0]`` to ``[1]``.
    """
    scale = abs(np.linalg.det(lin)) ** (1 / 3)
    sigmas = np.geomspace(*sigma_mm, max(rounds, 1))
    for sigma in sigmas[:rounds]:
        pts = cloud.points @ lin.T + t
        nrm = _rotate_normals(lin, cloud.normals)
        d, j, ok = scorer.match(pts, nrm)
        w = np.where(ok, np.exp(-0.5 * (d / sigma) ** 2), 0.0)
        keep = w > 1e-3
        if keep.sum() < 6:
            break
        src, dst, w = pts[keep], scorer.ref.points[j[keep]], w[keep]
        if seeds is not None:
            sp = seeds[0] @ lin.T + t
            src, dst = np.vstack([src, sp]), np.vstack([dst, seeds[1]])
            w = np.concatenate([w, np.full(len(sp), 0.2 * w.sum() / max(len(sp), 1))])
        r, tr = rigid_motion(src, dst, w)
        lin, t = r @ lin, r @ t + tr
    lin = lin * (scale / abs(np.linalg.det(lin)) ** (1 / 3))
    pts = cloud.points @ lin.T + t
    return lin, t, scorer.cost(pts, _rotate_normals(lin, cloud.normals))


def _rotate_normals(lin: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Outward normals under ``lin`` (a reflection keeps outward outward)."""
    n = normals @ lin.T
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def _fit_scale(
    scorer: _Scorer, cloud: _Cloud, lin: np.ndarray, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Uniform scale from matched pairs in both directions, on the overlap only."""
    for _ in range(4):
        pts = cloud.points @ lin.T + t
        nrm = _rotate_normals(lin, cloud.normals)
        d, j, ok = scorer.match(pts, nrm)
        fwd = ok & (d < 4.0)
        back_d, back_i = cKDTree(pts).query(scorer.ref.points)
        bwd = back_d < 4.0
        if fwd.sum() < 20 or bwd.sum() < 20:
            break
        a = np.vstack([pts[fwd], pts[back_i[bwd]]])
        b = np.vstack([scorer.ref.points[j[fwd]], scorer.ref.points[bwd]])
        ca, cb = a.mean(axis=0), b.mean(axis=0)
        s = np.sqrt(((b - cb) ** 2).sum() / ((a - ca) ** 2).sum())
        total = abs(np.linalg.det(lin)) ** (1 / 3) * s
        s *= np.clip(total, *SCALE_RANGE) / total
        lin, t = s * lin, s * (t - ca) + ca
        lin, t, _ = _icp(scorer, cloud, lin, t, rounds=4)
    return lin, t


def search_pose(
    target: Mesh,
    reference: Mesh,
    *,
    hint: tuple | None = None,
    seeds: tuple[np.ndarray, np.ndarray] | None = None,
    mirror: str = "auto",
    fit_scale: bool = True,
    n_samples: int = 1500,
    seed: int = 0,
) -> PoseResult:
    """Similarity mapping ``target`` (input frame, mm) onto ``reference``.

    Parameters
    ----------
    hint : (anterior, superior[, left]) in target coordinates, optional
        Directions known from the file (a sample registry, the user).  With
        ``left`` the handedness is given.
    seeds : (target_points, reference_points), optional
        Three or more corresponding points (user-placed landmarks).
    mirror : "auto" | "no" | "yes"
        Whether the reflected reading is tried, refused or forced.
    fit_scale : bool
        Fit a uniform scale after the orientation (otherwise 1).
    """
    if mirror not in ("auto", "no", "yes"):
        raise ValueError("mirror must be 'auto', 'no' or 'yes'")
    rng = np.random.default_rng(seed)
    ref = surface_samples(reference, 8 * n_samples, rng)
    everything = surface_samples(target, 4 * n_samples, rng)
    exposed = _exposed(target, everything)
    small = _Cloud(exposed.points[:150], exposed.normals[:150])
    cloud = _Cloud(exposed.points[:n_samples], exposed.normals[:n_samples])
    scorer = _Scorer(ref)
    searching = hint is None and not (seeds is not None and len(seeds[0]) >= 3)
    grid = _Grid(ref) if searching else None
    own = _Grid(surface_samples(target, 8 * n_samples, rng)) if searching else None
    handed_by = None
    rot_sets: dict[bool, list[np.ndarray]] = {}
    method = "search"
    if seeds is not None and len(seeds[0]) >= 3:
        method = "seeds"
        return _from_seeds(scorer, cloud, seeds, mirror, fit_scale)
    if hint is not None:
        method = "hint"
        rot, hinted_mirror = hint_rotation(*hint)
        if len(hint) > 2 and hint[2] is not None:
            handed_by = "hint"
            mirror = "yes" if hinted_mirror else "no"
        rot_sets = {False: [rot], True: [FLIP @ rot]}
    handedness = [False, True] if mirror == "auto" else [mirror == "yes"]
    if method == "search":
        # the shape cannot tell a mirrored skull (it is bilaterally symmetric): keep the
        # file's handedness unless told otherwise
        handedness = [mirror == "yes"]
        if grid is None or own is None:  # built above whenever the search runs
            raise RuntimeError("search_pose: the pose search needs the distance grids")
        planes = symmetry_planes(cloud, own)
    best: dict[bool, tuple[float, np.ndarray, np.ndarray]] = {}
    refined: dict[bool, list[tuple[float, np.ndarray, np.ndarray]]] = {h: [] for h in handedness}
    for flipped in handedness:
        f = FLIP if flipped else np.eye(3)
        if method == "hint":
            trials = []
            for r0 in rot_sets[flipped]:
                r = _width_scale(ref, cloud, r0[0]) * r0
                for shift in itertools.product((-36.0, -12.0, 12.0, 36.0), (-15.0, 15.0)):
                    t = (
                        ref.points.mean(axis=0)
                        - (small.points @ r.T).mean(axis=0)
                        + np.array([0.0, *shift])
                    )
                    lin, tt, c = _icp(scorer, small, r, t, rounds=5, sigma_mm=SEARCH_SIGMA_MM)
                    trials.append((c, lin, tt))
            trials.sort(key=lambda x: x[0])
            trials = trials[:4]
        else:
            flipped_small = _Cloud(small.points @ f.T, small.normals @ f.T)
            if grid is None:
                raise RuntimeError("search_pose: the pose search needs the reference grid")
            cands = []
            for _, u, d in planes:
                uf = f @ u
                s0 = _width_scale(ref, cloud, u)
                cands += _plane_poses(grid, flipped_small, uf, d, ref.points.mean(axis=0), s0)
            cands.sort(key=lambda x: x[0])
            trials = [(c, r @ f, t) for c, r, t in _distinct(cands, REFINED)]
        for c, lin, tt in trials:
            lin, tt, c = _icp(scorer, small, lin, tt, rounds=6, sigma_mm=SEARCH_SIGMA_MM)
            lin, tt, c = _icp(scorer, cloud, lin, tt, rounds=15)
            if method == "search":
                c += _face_coverage_loss(ref, everything, lin, tt)
                refined[flipped].append((c, lin, tt))
            if flipped not in best or c < best[flipped][0]:
                best[flipped] = (c, lin, tt)
    ratio = float("nan")
    if len(best) == 2:
        proper_cost, flipped_cost = best[False][0], best[True][0]
        choose = flipped_cost < MIRROR_MARGIN * proper_cost
        handed_by = "shape" if (choose or proper_cost < MIRROR_MARGIN * flipped_cost) else "assumed"
        ratio = float(max(proper_cost, flipped_cost) / max(min(proper_cost, flipped_cost), 1e-9))
    else:
        choose = handedness[0]
        handed_by = handed_by or "assumed"
    cost, lin, t = best[choose]

    def finish(lin: np.ndarray, t: np.ndarray, others: tuple[PoseResult, ...] = ()) -> PoseResult:
        if fit_scale:
            lin, t = _fit_scale(scorer, cloud, lin, t)
            lin, t, _ = _icp(scorer, cloud, lin, t, rounds=10)
        return _result(scorer, cloud, lin, t, choose, handed_by, ratio, method, others)

    others: tuple[PoseResult, ...] = ()
    if method == "search":
        ranked = sorted(refined[choose], key=lambda x: x[0])
        picked = [(cost, lin, t)]
        for cand in ranked:
            if len(picked) > ALTERNATIVES:
                break
            if all(
                _angle_deg(cand[1], r2) > DISTINCT_DEG or np.linalg.norm(cand[2] - t2) > 20.0
                for _, r2, t2 in picked
            ):
                picked.append(cand)
        others = tuple(finish(r, tt) for _, r, tt in picked[1:])
    return finish(lin, t, others)


def _from_seeds(
    scorer: _Scorer,
    cloud: _Cloud,
    seeds: tuple[np.ndarray, np.ndarray],
    mirror: str,
    fit_scale: bool,
) -> PoseResult:
    """Start from the seeds' similarity (both readings when allowed), refine with them held."""
    from workbench.core.tps import similarity_transform

    pts, ref_pts = np.asarray(seeds[0], float), np.asarray(seeds[1], float)
    options = []
    for flipped in (False, True) if mirror == "auto" else (mirror == "yes",):
        f = FLIP if flipped else np.eye(3)
        m = similarity_transform(pts @ f.T, ref_pts)
        lin = m[:3, :3] @ f
        resid = np.linalg.norm(pts @ lin.T + m[:3, 3] - ref_pts, axis=1)
        options.append((float(np.sqrt((resid**2).mean())), flipped, lin, m[:3, 3]))
    options.sort(key=lambda o: o[0])
    rms, flipped, lin, t = options[0]
    s = abs(np.linalg.det(lin)) ** (1 / 3)
    lin = lin * (np.clip(s, *SCALE_RANGE) / s)
    ratio = options[1][0] / max(rms, 1e-9) if len(options) == 2 else float("nan")
    handed_by = "seeds" if (len(options) == 1 or ratio > 1.5) else "assumed"
    if handed_by == "assumed" and len(options) == 2 and options[0][1]:
        # the seeds cannot tell (midline or symmetric seeds): keep the file's handedness
        rms, flipped, lin, t = next(o for o in options if not o[1])
    lin, t, _ = _icp(scorer, cloud, lin, t, rounds=20, seeds=(pts, ref_pts))
    if fit_scale:
        lin, t = _fit_scale(scorer, cloud, lin, t)
        lin, t, _ = _icp(scorer, cloud, lin, t, rounds=10, seeds=(pts, ref_pts))
    return _result(scorer, cloud, lin, t, flipped, handed_by, float(ratio), "seeds")


def _result(
    scorer: _Scorer,
    cloud: _Cloud,
    lin: np.ndarray,
    t: np.ndarray,
    mirrored: bool,
    handed_by: str,
    ratio: float,
    method: str,
    alternatives: tuple[PoseResult, ...] = (),
) -> PoseResult:
    pts = cloud.points @ lin.T + t
    nrm = _rotate_normals(lin, cloud.normals)
    d, _, ok = scorer.match(pts, nrm)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = lin, t
    return PoseResult(
        m,
        float(abs(np.linalg.det(lin)) ** (1 / 3)),
        bool(mirrored),
        scorer.cost(pts, nrm),
        float(np.mean(ok & (d < 2.0))),
        handed_by,
        ratio,
        method,
        alternatives,
    )
