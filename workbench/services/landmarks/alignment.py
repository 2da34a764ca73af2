"""Coarse alignment of a target surface (skull or skin scan) to the reference head.

Units: mm.  The result maps **target (input) coordinates into the head
frame** of the reference head (x to the subject's left, y up, z forward,
Frankfort Horizontal at y = 0).  It is a similarity (rotation, uniform scale,
translation), optionally composed with a left/right reflection when the
caller says the input is mirrored (e.g. a CT stored in a left-handed space).

How (the first step of Kähler's §8.4.2 assisted placement, done without
hand-placed landmarks when there are fewer than three):

1. Starting rotations: the one implied by an orientation hint (anterior and
   superior directions of the input, as the sample registry or a user
   gives them), else the 24 axis-permutation rotations of the input's
   principal axes matched to the reference's, plus the 24 axis-aligned ones.
2. Each start runs a few rounds of trimmed, scaled ICP between area-weighted
   surface samples (target → reference nearest neighbours in a k-d tree;
   only the best 70 % of pairs count, because the target is often partial
   — a CT cut above the orbits — or carries extra bone such as vertebrae).
3. The best starts are refined with more rounds; the winner has the lowest
   trimmed RMS distance.  A uniform scale is fitted only when the target
   covers the reference (pairs in both directions); for a partial target
   the alignment stays rigid, as a trimmed scaled ICP would shrink it (units
   are settled when the mesh is read, and the non-rigid warp that follows
   takes up size differences).  Seeds give a similarity.

With three or more seed landmarks whose codes the reference also carries,
the similarity is solved from them directly (Umeyama) and only refined.

Why not :func:`workbench.core.rigid_search.search_pose` (the skull
registration's and the scan fit's search)?  Its samples, rotations and hint
come from the same module, but its robust, scaled pose is made for a skull or
a face scan.  On a CT's whole skin (head and neck) without hints it shrank
the head to 0.80-0.81 of its size; the median distance of the suggested skin
landmarks to the truth (``tests/data/soft_tissue_truth``, both reference
heads, 2026-12-06) was 43-82 mm on the Visible Human male (this ICP: 7-12 mm)
and 54-80 mm on the female (this ICP: 35 mm); on headsq, whose skin holds an
airway tube, both miss (39-42 mm).  So the landmark transfer keeps this ICP.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from workbench.core import rigid_search
from workbench.core.errors import InputError
from workbench.core.frame import apply_transform
from workbench.core.mesh import Mesh
from workbench.core.tps import similarity_transform

SCALE_RANGE = (0.75, 1.33)
TRIM = 0.7
#: the target is "complete" when this fraction of the reference lies within 10 mm of it
COMPLETE = 0.7


@dataclass(frozen=True)
class Alignment:
    """Target → head-frame similarity.

    Attributes
    ----------
    matrix : (4, 4)
        Homogeneous map of target points into the head frame.
    scale : float
        Its uniform scale (|det|^(1/3)).
    rms_mm : float
        Trimmed RMS distance (best 70 % of target samples) after alignment.
    overlap : float
        Fraction of target samples within 5 mm of the reference after alignment.
    method : str
        "seeds" or "search".
    """

    matrix: np.ndarray
    scale: float
    rms_mm: float
    overlap: float
    method: str

    def apply(self, points: np.ndarray) -> np.ndarray:
        return apply_transform(self.matrix, points)

    def inverse(self, points: np.ndarray) -> np.ndarray:
        return apply_transform(np.linalg.inv(self.matrix), points)


def surface_samples(mesh: Mesh, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points spread over the surface with probability ∝ triangle area
    (:func:`workbench.core.rigid_search.surface_samples`, without the normals)."""
    try:
        return rigid_search.surface_samples(mesh, n, rng).points
    except ValueError:
        raise InputError("mesh", "has no surface area") from None


def hint_rotation(
    anterior: np.ndarray, superior: np.ndarray, left: np.ndarray | None = None
) -> np.ndarray:
    """Linear map of input directions to the head frame (rows: left, up, forward), with the
    reflection included when ``left`` says the input is mirrored (determinant −1); see
    :func:`workbench.core.rigid_search.hint_rotation`."""
    rot, mirrored = rigid_search.hint_rotation(anterior, superior, left)
    if mirrored:
        rot = rot.copy()
        rot[0] = -rot[0]
    return rot


def _icp(
    src: np.ndarray, tree: cKDTree, ref: np.ndarray, lin: np.ndarray, t: np.ndarray, rounds: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """Trimmed ICP, src (target samples) → ref (reference samples), keeping ``lin``'s scale.

    Scale is not re-estimated: with a partial target and trimming, a scaled
    ICP shrinks the target into the reference (the best 70 % of pairs get
    closer when everything gets smaller).  Units are settled before this
    (mm), and the non-rigid warp that follows takes up the size difference.
    """
    scale = abs(np.linalg.det(lin)) ** (1 / 3)
    for _ in range(rounds):
        moved = src @ lin.T + t
        d, j = tree.query(moved)
        keep = d <= np.quantile(d, TRIM)
        m = similarity_transform(moved[keep], ref[j[keep]])
        rot = m[:3, :3] / abs(np.linalg.det(m[:3, :3])) ** (1 / 3)
        # rigid update about the matched centroid
        c_s, c_r = moved[keep].mean(axis=0), ref[j[keep]].mean(axis=0)
        lin, t = rot @ lin, rot @ (t - c_s) + c_r
    lin = lin * (scale / abs(np.linalg.det(lin)) ** (1 / 3))
    d, _ = tree.query(src @ lin.T + t)
    rms = float(np.sqrt(np.mean(np.sort(d)[: max(1, int(TRIM * len(d)))] ** 2)))
    return lin, t, rms


def _scale_if_complete(
    src: np.ndarray, ref: np.ndarray, tree: cKDTree, lin: np.ndarray, t: np.ndarray, rms: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """Fit the uniform scale too, but only when the target covers the reference.

    Pairs are taken in both directions (target → reference and reference →
    target), so neither surface can shrink into the other; with a partial
    target the rigid result is returned unchanged.
    """
    moved = src @ lin.T + t
    d_back, _ = cKDTree(moved).query(ref)
    if np.mean(d_back < 10.0) < COMPLETE:
        return lin, t, rms
    for _ in range(15):
        moved = src @ lin.T + t
        _, j = tree.query(moved)
        _, k = cKDTree(moved).query(ref)
        a = np.vstack([moved, moved[k]])
        b = np.vstack([ref[j], ref])
        m = similarity_transform(a, b)
        lin, t = m[:3, :3] @ lin, m[:3, :3] @ t + m[:3, 3]
        scale = abs(np.linalg.det(lin)) ** (1 / 3)
        if not SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]:
            lin = lin * (np.clip(scale, *SCALE_RANGE) / scale)
    d, _ = tree.query(src @ lin.T + t)
    return lin, t, float(np.sqrt(np.mean(np.sort(d)[: max(1, int(TRIM * len(d)))] ** 2)))


def align_to_reference(
    target: Mesh,
    reference: Mesh,
    *,
    orientation: tuple | None = None,
    seeds: tuple[np.ndarray, np.ndarray] | None = None,
    n_samples: int = 1500,
    seed: int = 0,
) -> Alignment:
    """Similarity mapping ``target`` (input frame, mm) onto ``reference`` (head frame).

    Parameters
    ----------
    orientation : (anterior, superior[, left]) directions in target coordinates, optional
    seeds : (target_points, reference_points), optional
        Three or more corresponding points; used instead of the search.
    """
    rng = np.random.default_rng(seed)
    ref = surface_samples(reference, 4 * n_samples, rng)
    src = surface_samples(target, n_samples, rng)
    tree = cKDTree(ref)
    starts: list[np.ndarray] = []
    method = "search"
    if seeds is not None and len(seeds[0]) >= 3:
        # a similarity cannot turn a mirrored scan (e.g. a CT stored in a
        # left-handed space) into the reference: try the reflected reading
        # of the seeds too; the ICP below keeps each start's handedness and
        # the closer fit wins
        flip = np.diag([-1.0, 1.0, 1.0, 1.0])
        pts, ref_pts = np.asarray(seeds[0], float), np.asarray(seeds[1], float)
        starts = [
            similarity_transform(pts, ref_pts),
            similarity_transform(pts * [-1.0, 1.0, 1.0], ref_pts) @ flip,
        ]
        method = "seeds"
    else:
        if orientation is not None:
            rots = [hint_rotation(*orientation)]
        else:
            pa_s, pa_r = rigid_search.principal_axes(src), rigid_search.principal_axes(ref)
            turns = rigid_search.rotations_24()
            rots = [pa_r.T @ c @ pa_s for c in turns] + turns
        # the mesh is in mm by now (units are checked on reading), so start at
        # scale 1: a size ratio of radii is biased by partial scans
        scale0 = 1.0
        # partial scans (a CT cut above the orbits) shift the centroid, and
        # ICP from a partial onto a whole surface can slide: start from a few
        # offsets along the head's long axes too
        shifts = (
            [(0.0, dy, dz) for dy in (-40.0, -20.0, 0.0, 20.0, 40.0) for dz in (-20.0, 0.0, 20.0)]
            if len(rots) == 1
            else [(0.0, dy, 0.0) for dy in (-30.0, 0.0, 30.0)]
        )
        for r in rots:
            for shift in shifts:
                m = np.eye(4)
                m[:3, :3] = scale0 * r
                m[:3, 3] = ref.mean(0) - (src @ m[:3, :3].T).mean(0) + shift
                starts.append(m)
    trials = []
    for m in starts:
        lin, t, rms = _icp(src, tree, ref, m[:3, :3], m[:3, 3], rounds=6)
        trials.append((rms, lin, t))
    trials.sort(key=lambda x: x[0])
    best = None
    for _, lin, t in trials[:3]:
        lin, t, rms = _icp(src, tree, ref, lin, t, rounds=25)
        if best is None or rms < best[0]:
            best = (rms, lin, t)
    if best is None:
        raise RuntimeError("rigid alignment: no start pose to refine")
    rms, lin, t = best
    if method == "search":
        lin, t, rms = _scale_if_complete(src, ref, tree, lin, t, rms)
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = lin, t
    d, _ = tree.query(src @ lin.T + t)
    return Alignment(
        matrix, float(abs(np.linalg.det(lin)) ** (1 / 3)), rms, float(np.mean(d < 5.0)), method
    )
