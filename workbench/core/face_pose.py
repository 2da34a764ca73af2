"""Place the reference face on a scan by the face alone (scan fitting, issue 13).

Units mm.  :func:`workbench.core.rigid_search.search_pose` scores *scan*
samples against the reference, which is right for skulls with missing parts,
but on a bust most of the scan is not a face: Nefertiti's crown and
shoulders are ~75 % of the surface, so the best-scoring pose laid the
reference's scalp over the crown, its nose on the brow (the skin fit then
gave a face with two noses).  Here the direction is reversed: the
reference's *face* vertices look for the scan's surface, exactly
(:class:`~workbench.core.spatial.MeshIndex`, not samples), with normals that
agree.  A face the scan does not show cannot be where the scan is not, and
a crown, hair, shoulders or a plinth cost nothing because the face never
looks at them.

:func:`place_face` starts from a pose and sweeps sizes and shifts (up,
forward) around it: every start is scored once on scan samples, the best
are refined by a robust (Welsch) similarity ICP of the face onto the samples,
the best of those again onto the exact surface, and the pose with the lowest
face loss is returned – the mean over face vertices of ``1 − exp(−d²/2τ²)``
with ``d`` the distance to the scan (1 where the normals disagree or nothing
is near).  Rotation is only refined, not swept: a start turned by more than
~15° needs another start (the search's next-best poses).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.rigid_search import surface_samples
from workbench.core.spatial import MeshIndex
from workbench.core.threads import worker_count
from workbench.core.tps import similarity_transform

#: robust scale of the face loss (mm, in the reference's size)
LOSS_SCALE_MM = 4.0
#: a scan point matches a face vertex only when their normals agree this much (cosine)
MIN_COS = 0.3
#: Welsch scales of the refinement, first to last round (mm, reference size)
REFINE_SCALES_MM = (12.0, 3.0)
#: the sweep scores every start once, refines the best few on scan samples, and the
#: best of those again on the exact surface: counts and rounds
REFINED_STARTS, SAMPLE_ROUNDS = 12, 8
FINALISTS, FINAL_ROUNDS = 2, 10
#: relative sizes tried around the start (reference size / start size)
SIZE_STEPS = (0.8, 0.89, 1.0, 1.12, 1.25)
#: shifts of the reference face along its up and forward axes (mm): a bust's face can
#: lie a face-height away from where a pose scored on the whole bust put it
UP_SHIFTS_MM = tuple(np.arange(-90.0, 90.1, 15.0))
FORWARD_SHIFTS_MM = tuple(np.arange(-60.0, 60.1, 20.0))
#: face vertices scored by the sweep (a fixed, evenly spread subsample) ...
SWEEP_POINTS = 400
#: ... against this many area-weighted scan samples (distance error ≲ half their spacing)
SCAN_SAMPLES = 40_000


@dataclass(frozen=True)
class FacePlacement:
    """The reference face placed on the scan.

    Attributes
    ----------
    matrix : (4, 4)
        Scan (input, mm) → reference frame, a similarity (a reflection when
        the start was one), like ``PoseResult.matrix``.
    loss : float
        The face loss at ``matrix`` (0 perfect, 1 nothing matched).
    start_loss : float
        The face loss of the start pose as given.
    matched_fraction, near_fraction : float
        Face vertices with agreeing scan surface within 2.5 mm and 5 mm
        (reference size) at ``matrix``.
    near_by_group : dict
        ``near_fraction`` of each group of face vertices the caller named.
    """

    matrix: np.ndarray
    loss: float
    start_loss: float
    matched_fraction: float
    near_fraction: float
    near_by_group: dict[str, float] = field(default_factory=dict)

    @property
    def scale(self) -> float:
        return float(abs(np.linalg.det(self.matrix[:3, :3])) ** (1 / 3))


class _Face:
    """Reference face vertices and normals, and the scan they look for.

    ``exact`` matches go to the closest point of the scan surface; the others
    to the nearest of :data:`SCAN_SAMPLES` area-weighted samples (a k-d tree:
    ~10 times cheaper, for the sweep).
    """

    def __init__(self, points: np.ndarray, normals: np.ndarray, scan: MeshIndex):
        self.points = np.asarray(points, float)
        self.normals = np.asarray(normals, float)
        self.scan = scan
        cloud = surface_samples(scan.mesh, SCAN_SAMPLES, np.random.default_rng(0))
        self.samples, self.sample_normals = cloud.points, cloud.normals
        self.tree = cKDTree(self.samples)

    def match(
        self, g: np.ndarray, ids: np.ndarray, exact: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Under ``g`` (reference → scan): closest scan points, distances (reference mm), cosines."""
        lin = g[:3, :3]
        size = abs(np.linalg.det(lin)) ** (1 / 3)
        pts = self.points[ids] @ lin.T + g[:3, 3]
        n = self.normals[ids] @ lin.T
        # (the image of an outward normal stays outward under a reflection too)
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        if exact:
            cp = self.scan.closest_points(pts)
            # the normal of the closest feature, not of the face that holds it: at a closest
            # vertex or edge any of its faces may be returned (a tie the tree breaks), and
            # their normals differ; the fit then depended on the tree's layout
            cos = (self.scan.pseudo_normals(cp.face_ids, cp.barycentric) * n).sum(axis=1)
            return cp.points, cp.distances / size, cos
        d, j = self.tree.query(pts, workers=worker_count())
        return self.samples[j], d / size, (self.sample_normals[j] * n).sum(axis=1)

    def loss(self, g: np.ndarray, ids: np.ndarray, exact: bool = True) -> tuple[float, float]:
        """The face loss under ``g`` and the fraction matched within 2.5 mm."""
        _, d, cos = self.match(g, ids, exact)
        ok = cos > MIN_COS
        loss = np.where(ok, 1.0 - np.exp(-0.5 * (d / LOSS_SCALE_MM) ** 2), 1.0)
        return float(loss.mean()), float((ok & (d <= 2.5)).mean())

    def sample_losses(self, gs: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """The face loss on the scan samples under each of ``gs`` ``(k, 4, 4)``, at once."""
        lin = gs[:, :3, :3]
        size = np.abs(np.linalg.det(lin)) ** (1 / 3)
        pts = np.einsum("kij,mj->kmi", lin, self.points[ids]) + gs[:, None, :3, 3]
        n = np.einsum("kij,mj->kmi", lin, self.normals[ids])
        n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-12)
        # beyond 4 τ the loss is 1 anyway; a bounded query is ~10 times faster for the
        # many far-off starts
        bound = 4.0 * LOSS_SCALE_MM * float(size.max())
        d, j = self.tree.query(
            pts.reshape(-1, 3), distance_upper_bound=bound, workers=worker_count()
        )
        far = ~np.isfinite(d)
        j[far] = 0
        d = d.reshape(len(gs), -1) / size[:, None]
        cos = (self.sample_normals[j].reshape(n.shape) * n).sum(axis=2)
        cos[far.reshape(cos.shape)] = -1.0
        loss = np.where(cos > MIN_COS, 1.0 - np.exp(-0.5 * (d / LOSS_SCALE_MM) ** 2), 1.0)
        return loss.mean(axis=1)

    def near(self, g: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """Per face vertex: agreeing scan surface within 5 mm under ``g``."""
        _, d, cos = self.match(g, ids)
        return (cos > MIN_COS) & (d <= 5.0)

    def refine(
        self,
        g: np.ndarray,
        ids: np.ndarray,
        rounds: int,
        size_range: tuple[float, float],
        exact: bool = True,
    ) -> np.ndarray:
        """Robust similarity ICP of the face onto the scan; the size stays in ``size_range``."""
        flip = np.diag([-1.0, 1.0, 1.0]) if np.linalg.det(g[:3, :3]) < 0 else np.eye(3)
        src = self.points[ids] @ flip.T  # reflected once, the rest is a proper similarity
        for tau in np.geomspace(*REFINE_SCALES_MM, rounds):
            cp, d, cos = self.match(g, ids, exact)
            w = np.where(cos > MIN_COS, np.exp(-0.5 * (d / tau) ** 2), 0.0)
            if (w > 1e-3).sum() < 12:
                break
            m = similarity_transform(src, cp, w)
            size = abs(np.linalg.det(m[:3, :3])) ** (1 / 3)
            m[:3, :3] *= np.clip(size, *size_range) / size
            g = m.copy()
            g[:3, :3] = m[:3, :3] @ flip
        return g


def place_face(
    scan: MeshIndex,
    face_points: np.ndarray,
    face_normals: np.ndarray,
    start: np.ndarray,
    *,
    scale_range: tuple[float, float],
    groups: Mapping[str, np.ndarray] | None = None,
) -> FacePlacement:
    """The pose (scan → reference) that lays the reference face best on ``scan``.

    Parameters
    ----------
    scan : MeshIndex
        The scan in its input frame (mm).
    face_points, face_normals : (n, 3)
        The reference's face vertices and outward unit normals (reference frame, mm).
    start : (4, 4)
        A pose scan → reference (e.g. from ``search_pose``).
    scale_range : (lo, hi)
        Allowed scan → reference scales (as ``SCALE_RANGE``).
    groups : {name: indices into face_points}, optional
        Parts (the nose ...) whose near fractions are reported on their own.
    """
    face = _Face(face_points, face_normals, scan)
    n = len(face.points)
    every = np.arange(n)
    sweep = every[:: max(1, n // SWEEP_POINTS)]
    g0 = np.linalg.inv(start)  # reference → scan
    # reference → scan sizes are the inverse of the pose's scan → reference scales
    sizes = (1.0 / scale_range[1], 1.0 / scale_range[0])
    start_loss, _ = face.loss(g0, every)
    centre = face.points.mean(axis=0)
    grid = []
    for k, up, fwd in itertools.product(SIZE_STEPS, UP_SHIFTS_MM, FORWARD_SHIFTS_MM):
        # in the reference frame: scale about the face's centre, then shift (y up, z forward)
        local = np.eye(4)
        local[:3, :3] *= k
        local[:3, 3] = centre - k * centre + (0.0, up, fwd)
        g = g0 @ local
        size = abs(np.linalg.det(g[:3, :3])) ** (1 / 3)
        if sizes[0] * 0.98 <= size <= sizes[1] * 1.02:
            grid.append(g)
    losses = face.sample_losses(np.array(grid), sweep)
    starts = [(float(losses[i]), grid[i]) for i in np.argsort(losses, kind="stable")]
    refined = []
    for _, g in starts[:REFINED_STARTS]:
        g = face.refine(g, sweep, SAMPLE_ROUNDS, sizes, exact=False)
        refined.append((face.loss(g, sweep, exact=False)[0], g))
    refined.sort(key=lambda s: s[0])
    best_g, best_loss, best_match = g0, start_loss, face.loss(g0, every)[1]
    half = every[::2]
    for _, g in refined[:FINALISTS]:
        g = face.refine(g, half, FINAL_ROUNDS, sizes)
        loss, matched = face.loss(g, every)
        if loss < best_loss:
            best_g, best_loss, best_match = g, loss, matched
    near = face.near(best_g, every)
    by_group = {k: float(near[np.asarray(ids)].mean()) for k, ids in (groups or {}).items()}
    return FacePlacement(
        np.linalg.inv(best_g), best_loss, start_loss, best_match, float(near.mean()), by_group
    )
